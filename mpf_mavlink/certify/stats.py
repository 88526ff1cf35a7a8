"""The statistics of a certificate: distribution-free, from the sample size alone.

- :func:`flights_needed`: the smallest n with 1 - q^n >= confidence, so that the largest of n
  flights bounds the q-quantile with that confidence (59 for q = confidence = 0.95);
- :func:`quantile_interval`: the order-statistic confidence interval of a quantile (the ranks
  whose binomial probabilities bracket it), no distribution assumed;
- :func:`clopper_pearson`: the exact binomial interval of P(FAIL) from k failures in n flights.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from scipy import stats


def flights_needed(quantile: float = 0.95, confidence: float = 0.95) -> int:
    """Smallest n with 1 - quantile^n >= confidence: then P(max of n < the quantile) =
    quantile^n <= 1 - confidence, so the largest flight is a one-sided upper bound."""
    if not (0.0 < quantile < 1.0 and 0.0 < confidence < 1.0):
        raise ValueError("quantile and confidence must lie in (0, 1)")
    n = math.ceil(math.log(1.0 - confidence) / math.log(quantile))
    while 1.0 - quantile**n < confidence:  # guard the log's rounding
        n += 1
    while n > 1 and 1.0 - quantile ** (n - 1) >= confidence:
        n -= 1
    return n


def upper_bound_rank(n: int, quantile: float = 0.95, confidence: float = 0.95) -> int | None:
    """The smallest rank r (1-based, ascending) whose order statistic x_(r) is a one-sided
    upper confidence bound of the quantile: P(Binomial(n, quantile) < r) >= confidence.
    None when n flights are too few (x_(n) itself does not reach the confidence)."""
    for r in range(1, n + 1):
        if stats.binom.cdf(r - 1, n, quantile) >= confidence:
            return r
    return None


def quantile_interval(
    values: Sequence[float], quantile: float = 0.95, confidence: float = 0.95
) -> dict[str, float | int | None]:
    """The sample quantile and its distribution-free interval: the two-sided interval
    [x_(l), x_(u)] of coverage >= ``confidence`` (None on a side the sample cannot reach) and
    the one-sided upper bound x_(r) of :func:`upper_bound_rank`."""
    xs = sorted(float(v) for v in values)
    n = len(xs)
    if n == 0:
        return {"n": 0, "estimate": None, "low": None, "high": None, "upper_bound": None}
    est = float(_quantile(xs, quantile))
    a = (1.0 - confidence) / 2.0
    # l: the largest rank with P(B < l) <= a; u: the smallest rank with P(B < u) >= 1 - a
    lo_r = int(stats.binom.ppf(a, n, quantile))  # P(B <= lo_r) >= a
    hi_r = int(stats.binom.ppf(1.0 - a, n, quantile)) + 1
    low = xs[lo_r - 1] if lo_r >= 1 else None
    high = xs[hi_r - 1] if hi_r <= n else None
    r = upper_bound_rank(n, quantile, confidence)
    return {
        "n": n,
        "estimate": est,
        "low": low,
        "high": high,
        "low_rank": lo_r if lo_r >= 1 else None,
        "high_rank": hi_r if hi_r <= n else None,
        "upper_bound": xs[r - 1] if r is not None else None,
        "upper_bound_rank": r,
    }


def _quantile(xs: list[float], q: float) -> float:
    """The linear-interpolation sample quantile (numpy's default) of sorted ``xs``."""
    h = (len(xs) - 1) * q
    i = int(math.floor(h))
    j = min(i + 1, len(xs) - 1)
    return xs[i] + (h - i) * (xs[j] - xs[i])


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact two-sided interval of a binomial proportion from k successes in n trials:
    [Beta(a/2; k, n-k+1), Beta(1-a/2; k+1, n-k)] with 0 and 1 at the ends."""
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, n > 0 (got k = {k}, n = {n})")
    a = 1.0 - confidence
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2.0, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1.0 - a / 2.0, k + 1, n - k))
    return lo, hi
