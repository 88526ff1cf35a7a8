# C types for predict.py when it is compiled (python -m mpf_mavlink._build); predict.py stays
# the source and runs unchanged as Python. The prediction is scalar kinematics: typed as C
# doubles, it runs without a Python object per product.
cimport cython
# math.* as C calls that give Python's doubles and raise where it raises (_cmath.pxd)
cimport mpf_mavlink._cmath as math

@cython.locals(th2=double, th=double)
cpdef (double, double, double) _rodrigues(double x, double y, double z)

@cython.locals(th2=double, c1=double, c2=double)
cpdef tuple _exp(double x, double y, double z)

@cython.locals(th2=double, c1=double, c2=double, k_u=double)
cpdef (double, double, double) _turn(double x, double y, double z, double a, double b,
                                     double c)

@cython.locals(a00=double, a01=double, a02=double, a10=double, a11=double, a12=double,
               a20=double, a21=double, a22=double, b00=double, b01=double, b02=double,
               b10=double, b11=double, b12=double, b20=double, b21=double, b22=double)
cpdef tuple _mul(A, B)

@cython.locals(p0=double, p1=double, p2=double, e0=double, e1=double, e2=double, v=double,
               tau=double, dur=double, r0=double, r1=double, r2=double,
               a00=double, a01=double, a02=double, a10=double, a11=double, a12=double,
               a20=double, a21=double, a22=double, x=double, y=double, z=double,
               h0=double, h1=double, h2=double)
cpdef tuple predict_rows(vs, R_B_N, segments)
