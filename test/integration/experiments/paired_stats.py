# SPDX-License-Identifier: MIT
"""paired_stats: the statistics the experiment claim tests share (10 seeds, paired by seed):
means, paired differences with their t statistic and 95 % interval, and the Student-t quantiles
for 9 degrees of freedom."""
import math

T95_ONE_SIDED_DF9 = 1.833  # Student-t 0.95 quantile, 9 degrees of freedom (one-sided 95 % tests)
T975_DF9 = 2.262           # Student-t 0.975 quantile, 9 degrees of freedom (two-sided 95 % intervals)


def mean(xs):
    return sum(xs) / len(xs)


def paired(a, b):
    """Mean of a - b, its t statistic and its 95 % two-sided interval half-width (df 9)."""
    d = [x - y for x, y in zip(a, b)]
    n = len(d)
    m = mean(d)
    sd = math.sqrt(sum((x - m) ** 2 for x in d) / (n - 1))
    se = sd / math.sqrt(n)
    t = m / se if se > 0 else (math.inf if m > 0 else (-math.inf if m < 0 else 0.0))
    return m, t, T975_DF9 * se
