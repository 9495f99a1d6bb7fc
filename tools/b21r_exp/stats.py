# SPDX-License-Identifier: MIT
"""Statistics of the results: means with 95 % Student-t intervals across seeds, and the tests
every yes/no of the report comes from. Seeds are the independent units; comparisons of two
policies run on the same seed (same emulator noise, same evaluation poses) are paired."""
import math

import numpy as np
from scipy import stats as sps

LEVEL = 0.95
ALPHA = 1.0 - LEVEL


def mean_ci(values):
    """(mean, half-width of the 95 % t interval, n); half-width nan for n < 2, all nan for n = 0."""
    v = np.asarray([x for x in values if x is not None and not math.isnan(x)], dtype=float)
    n = len(v)
    if n == 0:
        return math.nan, math.nan, 0
    m = float(v.mean())
    if n < 2:
        return m, math.nan, n
    hw = float(sps.t.ppf(0.5 + LEVEL / 2, n - 1) * v.std(ddof=1) / math.sqrt(n))
    return m, hw, n


def paired(a, b, alternative):
    """Paired t-test of a against b (same seeds, in order). alternative: 'less' (a < b),
    'greater' (a > b) or 'two-sided'. Returns dict: n, mean_diff (a - b), ci (95 % of the
    difference), p, significant (p < 0.05). Pairs with a missing value are dropped."""
    pairs = [(x, y) for x, y in zip(a, b) if x is not None and y is not None and not (math.isnan(x) or math.isnan(y))]
    n = len(pairs)
    out = {"n": n, "test": "paired t-test (%s)" % alternative, "mean_diff": math.nan, "ci": math.nan,
           "p": math.nan, "significant": False}
    if n < 2:
        return out
    d = np.asarray([x - y for x, y in pairs], dtype=float)
    m, hw, _ = mean_ci(d)
    out["mean_diff"], out["ci"] = m, hw
    if np.all(d == d[0]):
        # No spread: the t statistic is undefined; the difference is exact.
        p = 0.0 if (alternative == "less" and d[0] < 0) or (alternative == "greater" and d[0] > 0) or \
            (alternative == "two-sided" and d[0] != 0) else 1.0
    else:
        p = float(sps.ttest_rel([x for x, _ in pairs], [y for _, y in pairs], alternative=alternative).pvalue)
    out["p"] = p
    out["significant"] = p < ALPHA
    return out


def welch(a, b, alternative):
    """Welch's t-test of independent samples a and b. Same fields as paired(); ci is the half-width
    of the two-sided 95 % interval of the difference."""
    a = [x for x in a if x is not None and not math.isnan(x)]
    b = [x for x in b if x is not None and not math.isnan(x)]
    out = {"n": (len(a), len(b)), "test": "Welch t-test (%s)" % alternative, "mean_diff": math.nan, "ci": math.nan,
           "p": math.nan, "significant": False}
    if len(a) < 2 or len(b) < 2:
        return out
    out["mean_diff"] = float(np.mean(a) - np.mean(b))
    # Half-width of the two-sided 95 % Welch interval of the difference, whatever the alternative.
    ci = sps.ttest_ind(a, b, equal_var=False).confidence_interval(confidence_level=LEVEL)
    out["ci"] = float(ci.high - ci.low) / 2.0
    p = float(sps.ttest_ind(a, b, equal_var=False, alternative=alternative).pvalue)
    out["p"] = p
    out["significant"] = p < ALPHA
    return out


def binomial(successes, n, p0, alternative):
    """Exact binomial test of a pooled success count against p0, with the Clopper-Pearson 95 %
    interval of the fraction."""
    out = {"n": n, "k": successes, "test": "exact binomial test (%s, p0 = %.3f)" % (alternative, p0),
           "fraction": math.nan, "lo": math.nan, "hi": math.nan, "p": math.nan, "significant": False}
    if n == 0:
        return out
    r = sps.binomtest(successes, n, p0, alternative=alternative)
    ci = r.proportion_ci(confidence_level=LEVEL, method="exact")
    out.update(fraction=successes / n, lo=float(ci.low), hi=float(ci.high), p=float(r.pvalue),
               significant=float(r.pvalue) < ALPHA)
    return out


def median_ci(values):
    """Median with its distribution-free 95 % interval (order statistics: the ranks k and n + 1 - k
    with P(Binomial(n, 1/2) < k) <= 2.5 %; for 10 values the 2nd and 9th, 97.9 % coverage).
    Values may be math.inf (censored: larger than any observed); nan and None are dropped.
    Returns (median, lo, hi, n); lo and hi nan when n is too small (n < 6) for a 95 % interval."""
    v = sorted(float(x) for x in values if x is not None and not math.isnan(x))
    n = len(v)
    if n == 0:
        return math.nan, math.nan, math.nan, 0
    med = v[n // 2] if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2.0
    k = 0
    while k + 1 <= n and sps.binom.cdf(k, n, 0.5) <= ALPHA / 2:
        k += 1
    if k == 0:
        return med, math.nan, math.nan, n
    return med, v[k - 1], v[n - k], n
