# C types for law.py when it is compiled (python -m mpf_mavlink._build); law.py stays the
# source and runs unchanged as Python. Every name below is a float of the paper's equations:
# typed as C doubles, the law's arithmetic runs without a Python object per product.
cimport cython

ctypedef (double, double, double) vec3_t

cpdef (double, double, double, double, double, double, double, double, double, double) \
    steady_state_frame(double u_f2, double u_f3, double v_w)

@cython.locals(wd11_dot=double, heading_dot=double, n_dot=double, m_climb_dot=double)
cpdef vec3_t steady_state_frame_rate(
    double wd11, double wd21, double wd31, double wd12, double wd22, double nn, double n,
    double wd21_dot, double wd31_dot)

cpdef (double, double, double, double, double) transient_direction(
    double y_w, double z_w, double alpha)

@cython.locals(n2=double, heading_dot=double, m_climb_dot=double)
cpdef vec3_t transient_frame_rate(
    double y_w, double z_w, double y_w_dot, double z_w_dot, double alpha, double nn1,
    double nn2)

@cython.locals(
    t=double, v_w=double, K_p=double, K_R=double, alpha=double,
    w1n=double, w2n=double, w3n=double, w1e=double, w2e=double, w3e=double,
    w1d=double, w2d=double, w3d=double, pn=double, pe=double, pd=double,
    hn=double, he=double, hd=double,
    xn=double, yn=double, zn=double, xe=double, ye=double, ze=double,
    xd=double, yd=double, zd=double, tn=double, te=double, td=double,
    vn=double, ve=double, vd=double, an=double, ae=double, ad=double,
    ox=double, oy=double, oz=double, dx=double, dy=double, dz=double,
    pdx=double, pdy=double, pdz=double, f1x=double, f1y=double, f1z=double,
    f2x=double, f2y=double, f2z=double, f3x=double, f3y=double, f3z=double,
    k1=double, k2=double, gx=double, gy=double, gz=double,
    tau=double, m_kappa_2=double, kappa_1=double,
    a0=double, a1=double, a2=double, b0=double, b1=double, b2=double,
    g0=double, g1=double, g2=double, cmd2=double, cmd3=double)
cpdef tuple mpf_law(double s, vehicle, target, path, gains, ext=*, diagnostics=*,
                    errors_mode=*)
