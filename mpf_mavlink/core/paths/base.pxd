# C types for base.py when it is compiled (python -m mpf_mavlink._build); base.py stays the
# source and runs unchanged as Python. The evaluation of a cell is all floats: typed as C
# doubles it runs without a Python object per product.
cimport cython
# math.* as C calls that give Python's doubles and raise where it raises (_cmath.pxd)
cimport mpf_mavlink._cmath as math

@cython.locals(
    si=double, p0=double, p1=double, p2=double, ta0=double, ta1=double, ta2=double,
    b0=double, b1=double, b2=double, c0=double, c1=double, c2=double,
    bb0=double, bb1=double, bb2=double, cc0=double, cc1=double, cc2=double,
    v0=double, v1=double, v2=double, twist=double, k1a=double, k1s=double, k2a=double,
    k2s=double, x=double, dp0=double, dp1=double, dp2=double, x2=double,
    ddp0=double, ddp1=double, ddp2=double, g=double, e0=double, e1=double, e2=double,
    cx=double, cy=double, cz=double, d=double, k=double, m=double,
    r0=double, r1=double, r2=double, nr=double, q0=double, q1=double, q2=double,
    ang=double, ca=double, sa=double, kappa_1=double, kappa_2=double, tau=double)
cpdef tuple _cell_point(tuple cell, double s)
