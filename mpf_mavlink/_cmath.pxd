# The math module as C calls, for the compiled hot paths (python -m mpf_mavlink._build): a
# module's .pxd that says "cimport mpf_mavlink._cmath as math" turns its .py's math.sin(x) into
# a C call instead of a Python one (~70 ns each, dozens a control step). Each function gives the
# same double as Python's math module (the same libm function) and raises where it raises
# (ValueError "math domain error", OverflowError "math range error"), so that pure and compiled
# modules agree bit for bit and fail alike. math.hypot is not here: Python computes it its own
# way, not with libm's hypot, so a module using it keeps Python's.
from libc cimport math as _m

cdef extern from "<math.h>":
    const double inf "INFINITY"
    const double nan "NAN"
    const double pi "M_PI"


cdef inline double _domain() except -1.0:
    raise ValueError("math domain error")


cdef inline double _range() except -1.0:
    raise OverflowError("math range error")


cdef inline bint isfinite(double x) noexcept:
    return _m.isfinite(x)


cdef inline double sqrt(double x) except? -1.0:
    if x < 0.0:
        return _domain()
    return _m.sqrt(x)


cdef inline double atan2(double y, double x) noexcept:
    return _m.atan2(y, x)


cdef inline double atan(double x) noexcept:
    return _m.atan(x)


cdef inline double sin(double x) except? -1.0:
    if _m.isinf(x):
        return _domain()
    return _m.sin(x)


cdef inline double cos(double x) except? -1.0:
    if _m.isinf(x):
        return _domain()
    return _m.cos(x)


cdef inline double tan(double x) except? -1.0:
    if _m.isinf(x):
        return _domain()
    return _m.tan(x)


cdef inline double asin(double x) except? -1.0:
    if x < -1.0 or x > 1.0:
        return _domain()
    return _m.asin(x)


cdef inline double exp(double x) except? -1.0:
    cdef double r = _m.exp(x)
    if _m.isinf(r) and _m.isfinite(x):
        return _range()
    return r


cdef inline double expm1(double x) except? -1.0:
    cdef double r = _m.expm1(x)
    if _m.isinf(r) and _m.isfinite(x):
        return _range()
    return r


cdef inline double radians(double x) noexcept:
    return x * (pi / 180.0)


cdef inline object ceil(double x):
    return int(_m.ceil(x))
