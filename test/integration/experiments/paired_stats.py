# SPDX-License-Identifier: MIT
"""paired_stats: what the experiment claim tests share (10 seeds, paired by seed): the sessions
themselves, means, paired differences with their t statistic and 95 % interval, the Student-t
quantiles for 9 degrees of freedom, and the report of the claims with the test's verdict."""
import concurrent.futures
import json
import math
import os
import subprocess
import tempfile

T95_ONE_SIDED_DF9 = 1.833  # Student-t 0.95 quantile, 9 degrees of freedom (one-sided 95 % tests)
T975_DF9 = 2.262           # Student-t 0.975 quantile, 9 degrees of freedom (two-sided 95 % intervals)


def run_sessions(exe, conf, jobs, prefix):
    """Runs b21r-experiment --config conf once per job (seed, [extra arguments]), two at a time (the
    machines have two cores), and returns the result documents in job order. Raises RuntimeError
    naming the command and its error output when a session fails."""
    with tempfile.TemporaryDirectory(prefix=prefix) as d:
        def one(numbered):
            i, (seed, args) = numbered
            out = os.path.join(d, "session-%d.json" % i)
            cmd = [exe, "--config", conf, "--seed", str(seed), *args, "--out", out]
            p = subprocess.run(cmd, capture_output=True, text=True)
            if p.returncode != 0:
                raise RuntimeError("%s: exit status %d: %s" % (" ".join(cmd), p.returncode, p.stderr))
            with open(out) as f:
                return json.load(f)

        with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
            return list(pool.map(one, enumerate(jobs)))


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


def report(results, asserted):
    """Prints each claim (results: name -> (holds, text)) with its status, then PASS or FAIL; the
    test fails when a claim that asserted[name] marks as asserted does not hold. Returns the exit
    status (0 or 1)."""
    failed = False
    for name, (ok, text) in results.items():
        status = "holds" if ok else ("FAILS" if asserted[name] else "does not hold (reported, not asserted)")
        print("%-15s %s: %s" % (name, status, text))
        failed = failed or (asserted[name] and not ok)
    print("FAIL" if failed else "PASS")
    return 1 if failed else 0
