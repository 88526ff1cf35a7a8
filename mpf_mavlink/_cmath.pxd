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


cdef inline double _checked(double r, double x, bint can_overflow) except? -1.0:
    """r = f(x) as Python's math module returns it (CPython's math_1): a NaN from a non-NaN x
    is a domain error, an infinity from a finite x a range error where f can overflow, else a
    domain error."""
    if _m.isnan(r) and not _m.isnan(x):
        raise ValueError("math domain error")
    if _m.isinf(r) and _m.isfinite(x):
        if can_overflow:
            raise OverflowError("math range error")
        raise ValueError("math domain error")
    return r


cdef inline bint isfinite(double x) noexcept:
    return _m.isfinite(x)


cdef inline double atan2(double y, double x) noexcept:
    return _m.atan2(y, x)


cdef inline double atan(double x) noexcept:
    return _m.atan(x)


cdef inline double sqrt(double x) except? -1.0:
    return _checked(_m.sqrt(x), x, False)


cdef inline double sin(double x) except? -1.0:
    return _checked(_m.sin(x), x, False)


cdef inline double cos(double x) except? -1.0:
    return _checked(_m.cos(x), x, False)


cdef inline double tan(double x) except? -1.0:
    return _checked(_m.tan(x), x, False)


cdef inline double asin(double x) except? -1.0:
    return _checked(_m.asin(x), x, False)


cdef inline double exp(double x) except? -1.0:
    return _checked(_m.exp(x), x, True)


cdef inline double expm1(double x) except? -1.0:
    return _checked(_m.expm1(x), x, True)


cdef inline double radians(double x) noexcept:
    return x * (pi / 180.0)


cdef inline object ceil(double x):
    return int(_m.ceil(x))
