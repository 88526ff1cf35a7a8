# C types for estimator.py when it is compiled (python -m mpf_mavlink._build); estimator.py
# stays the source and runs unchanged as Python. The plausibility checks of every sample and
# the wind frame of every estimate are scalar arithmetic: typed as C doubles, they run without
# a Python object per product. Numbers that may arrive as anything (float(x) of a field) stay
# Python objects, so a bad sample fails the same way compiled and pure.
cimport cython
# math.* as C calls that give Python's doubles and raise where it raises (_cmath.pxd)
cimport mpf_mavlink._cmath as math

@cython.locals(n=double, a=double, b=double, c=double, h=double, e=double, f=double,
               g=double)
cpdef tuple wind_frame_rows(double vx, double vy, double vz)

@cython.locals(x=double, y=double, z=double)
cpdef bint _vec3_ok(a, double bound)

@cython.locals(x0=double, y0=double, z0=double, x1=double, y1=double, z1=double, x2=double,
               y2=double, z2=double, b=double, tol=double, det=double)
cpdef bint _rotation_ok(a)
