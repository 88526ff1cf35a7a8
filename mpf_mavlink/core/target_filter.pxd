# C types for target_filter.py when it is compiled (python -m mpf_mavlink._build);
# target_filter.py stays the source and runs unchanged as Python. The filter's transition and
# updates are hand-unrolled scalars: typed as C doubles they run without a Python object per
# product.
cimport cython
# math.* as C calls that give Python's doubles and raise where it raises (_cmath.pxd)
cimport mpf_mavlink._cmath as math

@cython.locals(wT=double, cw=double, sw=double, s=double, c=double, ds=double, dc=double)
cpdef (double, double, double, double, double, double) _turn_terms(double w, double T)

@cython.locals(n=double, e=double, d=double, vn=double, ve=double, vd=double, w=double)
cpdef tuple _mean(x, double T, double cw, double sw, double s, double c)

@cython.locals(vn=double, ve=double, f06=double, f16=double,
               p00=double, p01=double, p02=double, p03=double, p04=double, p11=double,
               p12=double, p13=double, p14=double, p22=double, p23=double, p24=double,
               p33=double, p34=double, p44=double, pdd=double, pdv=double, pvv=double,
               var=double, pi_i=double, pi_2=double, pi_3=double, pi_4=double, a=double,
               b=double, f=double)
cpdef double _position_variance(x, Ph, Pv, double T, double s, double c, double ds,
                                double dc)

@cython.locals(vn=double, ve=double, w=double, cw=double, sw=double, s=double, c=double,
               ds=double, dc=double, a=double, b=double, g=double, h=double,
               p00=double, p01=double, p02=double, p03=double, p04=double, p11=double,
               p12=double, p13=double, p14=double, p22=double, p23=double, p24=double,
               p33=double, p34=double, p44=double,
               B00=double, B01=double, B02=double, B03=double, B11=double, B12=double,
               B13=double, B20=double, B21=double, B22=double, B23=double, B30=double,
               B31=double, B32=double, B33=double, B40=double, B41=double, B42=double,
               B43=double, qh=double, qv=double, qw=double, q3=double, q2=double, q1=double,
               pdd=double, pdv=double, pvv=double, dv=double)
cpdef tuple _predict(x, Ph, Pv, double T, q)

cpdef double _innovation(double s, double nu, double g)

@cython.locals(c0=double, c1=double, c2=double, c3=double, c4=double, s=double, g=double,
               k0=double, k1=double, k2=double, k3=double, k4=double, x0=double, x1=double,
               x2=double, x3=double, x4=double, nu=double,
               p00=double, p01=double, p02=double, p03=double, p04=double, p11=double,
               p12=double, p13=double, p14=double, p22=double, p23=double, p24=double,
               p33=double, p34=double, p44=double, f=double)
cpdef tuple _update_horizontal(xh, Ph, int i, double z, double r)

@cython.locals(pdd=double, pdv=double, pvv=double, c0=double, c1=double, s=double, g=double,
               k0=double, k1=double, nu=double, f=double)
cpdef tuple _update_vertical(xv, Pv, int i, double z, double r)
