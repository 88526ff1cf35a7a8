# C types for adapter.py when it is compiled (python -m mpf_mavlink._build); adapter.py stays
# the source and runs unchanged as Python. Names that may hold None (the memory's "not yet")
# stay Python objects; the rest are C doubles, and the helpers called at every step take and
# return them without a Python object between them.
cimport cython
# math.* as C calls that give Python's doubles and raise where it raises (_cmath.pxd)
cimport mpf_mavlink._cmath as math

@cython.locals(fx=double, fy=double, fz=double, d=double, k=double, nx=double, ny=double,
               nz=double, nn=double, rx=double, ry=double, rz=double, bank=double, load=double)
cpdef (double, double) bank_and_load_factor(w1, accel, double g=*)

cpdef double _clip(double x, double lo, double hi)

@cython.locals(cr=double, sr=double, cp=double, sp=double, cy=double, sy=double)
cpdef (double, double, double, double) _euler_to_quat_wxyz(double roll, double pitch, double yaw)

@cython.locals(dx=double, dy=double, dz=double, h2=double, h=double)
cpdef (double, double) heading_and_path_angle_rates(w1, omega)

cpdef double roll_rate_gain(double tau_roll_s, double hold_s)

@cython.locals(roll=double, pitch=double, ox=double, oy=double, oz=double, v=double,
               bank=double, n=double, k_turn=double, gamma=double, chid=double,
               gamd_law=double, v_sp=double, lead0=double, bal=double, gamd=double, p=double,
               q=double, r=double, q_bias=double, trim=double, pitch_sp=double, thrust=double,
               qw=double, qx=double, qy=double, qz=double)
cpdef tuple adapt(omega_w1_I, airspeed, R_B_N, w1, dt, params, state=*, double g=*, meas=*,
                  hold_s=*, airspeed_sp=*, path_down_m=*)

@cython.locals(r=double)
cpdef double reserve_airspeed(double v_sp, double v_max, double climb, double max_climb,
                              double gust, double gust_s, double g=*)

@cython.locals(trim=double, pitch_sp=double)
cpdef (double, double) _pitch_setpoint(params, trim_hat, double gamma, double gamd)

@cython.locals(sphi=double, cphi=double, sth=double, cth=double, phid=double, p=double,
               lead=double, gamd_b=double, q_turn=double, q_bias=double, q_law=double,
               q=double, r=double, q_free=bint)
cpdef (double, double, double, double, bint) _body_rates(
    params, state, meas, double dt, double hold_s, double roll, double pitch, double bank,
    double chid, double gamd)

@cython.locals(ff=double, gamma_law=double, gamma_c=double, thrust=double, integ=double)
cpdef tuple _thrust(params, state, double v, double v_sp, double gamma, double gamd_law,
                    double trim, double n, double bal, double dt, double g)

@cython.locals(base=double, raw=double, lo=double, hi=double)
cpdef (double, double) _airspeed_pi(params, double integ, double e, double ff, double dt)

@cython.locals(integ=double, vdot_f=double, bal=double, a=double, vsp_dot=double,
               tau_v=double, vdot_c=double, e_E=double, base=double, lim=double, raw=double,
               lo=double, hi=double, thrust=double, law=double)
cpdef tuple energy_thrust(params, st, double v, double v_sp, double gamma, double gamma_c,
                          double ff, double dt, double g=*, gamma_law=*)

@cython.locals(k=double, u=double, sus=double, off=double, w=double, span=double,
               target=double, b=double)
cpdef double _priority_balance(p, double bal, double unmet, double v, double gamma_c,
                               double law, double dt)

@cython.locals(b=double, q_m=double, lim=double)
cpdef double _pitch_rate_bias(params, state, meas, double dt, double q_turn)

@cython.locals(k_turn=double, phi=double, theta=double, q_m=double, r_m=double, off=double,
               lim=double, pitch_sp=double, pushing_out=bint, psid=double, pred=double,
               err=double, a=double)
cpdef tuple _learn(params, state, meas, w1, double v, double dt, double g, double gamd,
                   double gamma, freeze_trim=*)
