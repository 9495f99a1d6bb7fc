# SPDX-License-Identifier: MIT
"""What the figures and the report show, computed once from the result files: learning curves
across seeds, the comparators, and each claim of the paper with the test that decides it.

Every claim is a dict: paper (what the paper says), measure (what we compare, with numbers),
test (name and p), holds (True / False / None when the data cannot decide), and n (seeds)."""
import math

from b21r_exp import results, stats

PAPER_HOURS = 2.0  # "all of the training was accomplished in approximately two hours"
PAPER_TABLE1 = {1.0: (46.2, 2.03), 2.0: (25.0, 6.24), 3.0: (18.7, 6.54)}
PAPER_FIRST_OBSTACLE_SUCCESS = 15  # phase-one runs before the first evaluation success (Fig. 9)
PAPER_FIRST_REWARD_H = 2.0  # Fig. 6: "the fastest ... was slightly over two hours"
EXPLORE_PREFIX = "explore_"  # the sensitivity study's experiment files (tools/experiments/explore_*.conf)


def fmt_ci(m, hw, digits=1):
    if m is None or math.isnan(m):
        return "n/a"
    if hw is None or math.isnan(hw):
        return "%.*f" % (digits, m)
    return "%.*f ± %.*f" % (digits, m, digits, hw)


def fmt_p(p):
    return "n/a" if p is None or math.isnan(p) else ("p < 0.001" if p < 0.001 else "p = %.3f" % p)


def claim(paper, measure, test, holds, n):
    return {"paper": paper, "measure": measure, "test": test, "holds": holds, "n": n}


def paired_claim(paper, a_name, a, b_name, b, alternative, holds_if_significant=True):
    t = stats.paired(a, b, alternative)
    ma, ha, n = stats.mean_ci(a)
    mb, hb, _ = stats.mean_ci(b)
    measure = "%s %s vs %s %s steps; difference %s" % (a_name, fmt_ci(ma, ha), b_name, fmt_ci(mb, hb),
                                                      fmt_ci(t["mean_diff"], t["ci"]))
    holds = None if t["n"] < 2 else (t["significant"] if holds_if_significant else not t["significant"])
    return claim(paper, measure, "%s, %s, n = %d seeds" % (t["test"], fmt_p(t["p"]), t["n"]), holds, t["n"])


def learn_curve(seeds):
    """Per evaluation block across seeds: training runs, phase, mean_all/mean_succ/successes
    (mean, ci), and the fraction of seeds already in phase two."""
    n_blocks = min(len(s["blocks"]) for s in seeds)
    curve = []
    for i in range(n_blocks):
        bs = [s["blocks"][i] for s in seeds]
        curve.append({
            "training_runs": bs[0]["training_runs"],
            "phase2_fraction": sum(1 for b in bs if b["phase"] == 2) / len(bs),
            "mean_all": stats.mean_ci([b["mean_all"] for b in bs]),
            "mean_succ": stats.mean_ci([b["mean_succ"] for b in bs]),
            "successes": stats.mean_ci([b["successes"] for b in bs]),
            "store_fill": stats.mean_ci([b["store_fill"] for b in bs]),
        })
    return curve


def learn_summary(rs):
    seeds = [results.learn_seed(r) for r in rs]
    refs = sorted({k for s in seeds for k in s["refs"]})
    return {
        "n": len(seeds),
        "seeds": seeds,
        "seed_list": [s["seed"] for s in seeds],
        "curve": learn_curve(seeds),
        "best_example": stats.mean_ci([s["best_example"] for s in seeds]),
        "mean_example": stats.mean_ci([s["mean_example"] for s in seeds]),
        "refs": {k: stats.mean_ci([s["refs"][k]["mean_all"] for s in seeds if k in s["refs"]]) for k in refs},
        "training_hours": stats.mean_ci([s["training_hours"] for s in seeds]),
        "eval_hours": stats.mean_ci([s["eval_hours"] for s in seeds]),
        "switch_after": stats.mean_ci([s["switch_after"] for s in seeds if s["switch_after"] is not None]),
        "hours_to_switch": stats.mean_ci([s["training_hours_to_switch"] for s in seeds]),
        "phase_two_sources": {k: stats.mean_ci([s["phase_two_sources"][k] for s in seeds])
                              for k in results.SOURCES},
        "wall_s": sum(s["wall_s"] for s in seeds),
        "step_limit": seeds[0]["step_limit"],
    }


def _col(seeds, key, sub=None):
    out = []
    for s in seeds:
        v = s.get(key)
        if v is None:
            out.append(math.nan)
        elif sub is not None:
            out.append(v[sub] if not isinstance(v, dict) or sub in v else math.nan)
        else:
            out.append(v)
    return out


def ref_col(seeds, name):
    return [s["refs"][name]["mean_all"] if name in s["refs"] else math.nan for s in seeds]


def ref_label(name):
    """A reference's name for people: example@2 -> "example policy at gain 2"."""
    if name == "example":
        return "example policy at its nominal gain"
    if name.startswith("example@"):
        return "example policy at gain %s" % name[len("example@"):]
    return {"optimal": "optimal controller", "human": "simulated human driver"}.get(name, name)


def example_refs(S):
    """The example references the experiment evaluated: the nominal gain and each example@GAIN."""
    return sorted(k for k in S["refs"] if k == "example" or k.startswith("example@"))


def best_example_ref(S):
    """The example reference with the fewest mean steps over the seeds from the same poses, or None
    when the experiment evaluated none."""
    names = example_refs(S)
    return min(names, key=lambda k: (S["refs"][k][0], k)) if names else None


def corridor_claims(S, human):
    """Claims of Figs. 4 and 5 (corridor)."""
    seeds = S["seeds"]
    n = S["n"]
    out = []
    p1 = _col(seeds, "last_phase_one", "mean_all")
    fin = _col(seeds, "final", "mean_all")
    first2 = _col(seeds, "first_phase_two", "mean_all")
    if not human:
        out.append(paired_claim(
            "After 30 phase-one runs the learned policy is significantly better (95 %) than the shortest "
            "phase-one training run (\"best example\").",
            "learned, last phase-one block", p1, "best example (shortest phase-one run; jittered starts)",
            _col(seeds, "best_example"), "less"))
        best = best_example_ref(S)
        if best is not None:
            gains = example_refs(S)
            of = "the best of %d gains evaluated" % len(gains) if len(gains) > 1 else "the only gain evaluated"
            out.append(paired_claim(
                "(Fair form of the same claim) better than the example policy at its best gain (%s), evaluated "
                "from the same 10 poses." % of,
                "learned, last phase-one block", p1, "%s, same poses" % ref_label(best), ref_col(seeds, best), "less"))
            out.append(paired_claim(
                "(Issue 10) After phase one the learned policy is at least as good as the example policy at its best "
                "gain, same poses (tested as: not significantly worse, one-sided).",
                "learned, last phase-one block", p1, "%s, same poses" % ref_label(best), ref_col(seeds, best),
                "greater", holds_if_significant=False))
    else:
        out.append(paired_claim(
            "After phase two the learned policy is significantly better than the phase-one (human) runs.",
            "learned, final block", fin, "mean phase-one run (other start poses, same seed)",
            _col(seeds, "mean_example"), "less"))
        if any("human" in s["refs"] for s in seeds):
            out.append(paired_claim(
                "(Fair form: same poses) After phase two the learned policy is significantly better than the "
                "human driver evaluated from the same 10 poses.",
                "learned, final block", fin, "simulated human driver, same poses",
                ref_col(seeds, "human"), "less"))
        out.append(paired_claim(
            "(Stronger) better than the proportional example policy evaluated from the same 10 poses.",
            "learned, final block", fin, "proportional example policy at its nominal gain, same poses",
            ref_col(seeds, "example"), "less"))
    out.append(paired_claim(
        "At the end the learned policy is indistinguishable (95 %) from \"optimal\" (tested as: not "
        "significantly worse, one-sided).",
        "learned, final block", fin, "optimal controller, same poses", ref_col(seeds, "optimal"), "greater",
        holds_if_significant=False))
    out.append(paired_claim(
        "The first evaluation after the switch is worse than the last phase-one evaluation (the dip).",
        "first phase-two block", first2, "last phase-one block", p1, "greater"))
    out.append(paired_claim(
        "After the dip the learned policy keeps improving in phase two.",
        "final block", fin, "first phase-two block", first2, "less"))
    all10 = [all(b["successes"] == b["n"] for b in s["phase_two_blocks"]) for s in seeds]
    out.append(claim("(Issue 10) The goal is reached from all 10 poses in every phase-two block.",
                     "%d of %d seeds" % (sum(all10), n), "count (every seed must)", n > 0 and all(all10), n))
    return out


def obstacle_claims(S):
    seeds = S["seeds"]
    n = S["n"]
    out = []
    firsts = [s["first_success_after"] for s in seeds]
    found = [f for f in firsts if f is not None]
    m, hw, k = stats.mean_ci(found)
    out.append(claim(
        "The learned policy first reaches the goal after about %d phase-one runs (Fig. 9)." % PAPER_FIRST_OBSTACLE_SUCCESS,
        "first block with a success after %s training runs (%d of %d seeds ever succeed)" % (fmt_ci(m, hw), k, n),
        "mean with 95 %% CI; the paper's value inside the interval: %s" % (
            "yes" if k >= 2 and abs(m - PAPER_FIRST_OBSTACLE_SUCCESS) <= hw else "no"),
        None if k < 2 else abs(m - PAPER_FIRST_OBSTACLE_SUCCESS) <= hw, k))
    fin_succ = _col(seeds, "final", "successes")
    all10 = sum(1 for x in fin_succ if x == 10)
    out.append(claim("Once it reaches the goal from one pose it quickly learns to reach it from all of them.",
                     "final block: %s of 10 poses reached; all 10 in %d of %d seeds" % (
                         fmt_ci(*stats.mean_ci(fin_succ)[:2]), all10, n),
                     "count (every seed must reach all 10 in the final block)", n > 0 and all10 == n, n))
    out.append(paired_claim(
        "The final steps to the goal are not significantly different (95 %) from \"optimal\" (successful runs).",
        "learned, final block (successful runs)", _col(seeds, "final", "mean_succ"),
        "optimal controller (successful runs), same poses",
        [s["refs"]["optimal"]["mean_succ"] if "optimal" in s["refs"] else math.nan for s in seeds], "two-sided",
        holds_if_significant=False))
    out.append(paired_claim(
        "The slight decrease just after the phase switch (steps, failures at the step limit).",
        "first phase-two block", _col(seeds, "first_phase_two", "mean_all"), "last phase-one block",
        _col(seeds, "last_phase_one", "mean_all"), "greater"))
    return out


def doorway_claims(S):
    """Claims of the doorway task (not in the paper; the issue's): the learner against the sloppy
    example policy and the reference controller, from the same 10 poses, failures at the step limit."""
    seeds = S["seeds"]
    n = S["n"]
    fin = _col(seeds, "final", "mean_all")
    out = [paired_claim(
        "After phase two the learned policy is better than the sloppy example policy at its nominal gain, "
        "evaluated from the same 10 poses (failures at the step limit).",
        "learned, final block", fin, "example policy at its nominal gain, same poses", ref_col(seeds, "example"),
        "less")]
    best = best_example_ref(S)
    if best is not None and best != "example":
        out.append(paired_claim(
            "... and better than the example policy at its best gain evaluated (%s)." % ref_label(best),
            "learned, final block", fin, "%s, same poses" % ref_label(best), ref_col(seeds, best), "less"))
    out.append(paired_claim(
        "After phase two the learned policy is better than the phase-one (example) runs it learned from.",
        "learned, final block", fin, "mean phase-one run (jittered starts, failures at the step limit)",
        _col(seeds, "mean_example"), "less"))
    out.append(paired_claim(
        "At the end the learned policy is not significantly worse than the reference controller (one-sided).",
        "learned, final block", fin, "reference (\"optimal\") controller, same poses", ref_col(seeds, "optimal"),
        "greater", holds_if_significant=False))
    fin_succ = _col(seeds, "final", "successes")
    all10 = sum(1 for x in fin_succ if x == 10)
    out.append(claim("The learned policy passes the door and reaches the goal from all 10 poses in the final block.",
                     "final block: %s of 10 poses reached; all 10 in %d of %d seeds" % (
                         fmt_ci(*stats.mean_ci(fin_succ)[:2]), all10, n),
                     "count (every seed must)", n > 0 and all10 == n, n))
    return out


def outcome_counts(rs):
    """Per seed, how runs ended: {"train": {phase: Counter}, "eval_final": Counter, "eval_all": Counter}
    summed over seeds (goal / collision / step_limit / aborted), from the result files' run lists."""
    out = {"train_1": {}, "train_2": {}, "eval_final": {}, "eval_all": {}}
    for r in rs:
        L = r["learning"]
        last = L["blocks"][-1]["block"] if L["blocks"] else None
        for x in L["runs"]:
            keys = ["train_%d" % x["phase"]] if x["kind"] == "train" else ["eval_all"] + (
                ["eval_final"] if x.get("block") == last else [])
            for k in keys:
                out[k][x["outcome"]] = out[k].get(x["outcome"], 0) + 1
    return out


def hours_claim(S):
    m, hw, n = S["training_hours"]
    holds = None if n < 2 else abs(m - PAPER_HOURS) <= max(hw, 0.5)
    return claim("All of the training took approximately two hours of driving.",
                 "%s h of training driving (plus %s h of evaluation runs)" % (fmt_ci(m, hw, 2), fmt_ci(*S["eval_hours"][:2], 2)),
                 "mean with 95 % CI across seeds; \"approximately two hours\" taken as within ±0.5 h", holds, n)


def explore_corridor_summary(variants):
    rows = []
    for var, rs in sorted(variants.items(), key=lambda kv: float(results.variant_value(kv[0]) or 0)):
        seeds = [results.explore_seed(r) for r in rs]
        times = [t for s in seeds for t, ok in zip(s["times_h"], s["success"]) if ok]
        rows.append({"limit": float(results.variant_value(var)), "n_seeds": len(seeds),
                     "runs": sum(s["runs"] for s in seeds), "successes": sum(s["successes"] for s in seeds),
                     "hours": stats.mean_ci([s["mean_hours_succ"] for s in seeds]),
                     "min_h": min(times) if times else math.nan,
                     "median_h": sorted(times)[len(times) // 2] if times else math.nan,
                     "times_h": times, "seeds": [s["seed"] for s in seeds],
                     "wall_s": sum(s["wall_s"] for s in seeds), "limit_h": seeds[0]["limit_h"]})
    return rows


def explore_goal_summary(variants):
    rows = []
    for var, rs in sorted(variants.items(), key=lambda kv: float(results.variant_value(kv[0]) or 0)):
        seeds = [results.explore_seed(r) for r in rs]
        d = float(results.variant_value(var))
        k = sum(s["successes"] for s in seeds)
        n = sum(s["runs"] for s in seeds)
        paper = PAPER_TABLE1.get(d)
        rows.append({"distance": d, "n_seeds": len(seeds), "runs": n, "successes": k,
                     "fraction": stats.mean_ci([s["fraction"] for s in seeds]),
                     "pooled": stats.binomial(k, n, paper[0] / 100.0 if paper else 0.5, "two-sided"),
                     "hours": stats.mean_ci([s["mean_hours_succ"] for s in seeds]),
                     "paper": paper, "seeds": [s["seed"] for s in seeds],
                     "wall_s": sum(s["wall_s"] for s in seeds), "limit_h": seeds[0]["limit_h"]})
    return rows


def against_references(S):
    """A variant's final block against its own references from the same poses, paired by seed:
    the example policy at its nominal gain (the middle of the range the variant's runs drew
    from) and the optimal controller. Returns {"final_succ": mean_ci, ref: {"mean": mean_ci,
    "diff": paired}} for each reference the variant evaluated."""
    seeds = S["seeds"]
    fin = _col(seeds, "final", "mean_all")
    out = {"final_succ": stats.mean_ci(_col(seeds, "final", "mean_succ"))}
    for ref in ("example", "optimal"):
        if ref in S["refs"]:
            col = ref_col(seeds, ref)
            out[ref] = {"mean": stats.mean_ci(col), "diff": stats.paired(fin, col, "two-sided")}
    return out


def ablation_comparisons(variants):
    """Every variant against the first one (the baseline order of experiment.vary), paired by seed:
    final block (failures at the step limit), training hours, phase switch point."""
    names = list(variants.keys())
    summ = {v: learn_summary(rs) for v, rs in variants.items()}
    base = names[0]
    comps = []
    for v in names[1:]:
        a = {s["seed"]: s for s in summ[v]["seeds"]}
        b = {s["seed"]: s for s in summ[base]["seeds"]}
        common = sorted(set(a) & set(b))
        fa = [a[s]["final"]["mean_all"] for s in common]
        fb = [b[s]["final"]["mean_all"] for s in common]
        ha = [a[s]["training_hours"] for s in common]
        hb = [b[s]["training_hours"] for s in common]
        comps.append({"variant": v, "baseline": base,
                      "final": stats.paired(fa, fb, "two-sided"),
                      "hours": stats.paired(ha, hb, "two-sided"),
                      "same_data": all(a[s]["digest"] == b[s]["digest"] for s in common)})
    return summ, comps


# ---- reference learners against the product's learner, by training steps ----------------------

# The product's own learner beside the reference learners, from whichever of these results exist:
# (experiment, variant, label). All run the 10 m corridor on the emulated B21r: HEDGER's greedy
# policy (the default) and the actor (policy = actor, actor_corridor), each from the Fig. 4
# examples and from the gentle teacher, and both from the sloppy human's examples
# (corridor_human_10m).
PRODUCT_PROGRESS = (
    ("fig4_corridor_examples", "", "product: greedy policy (HEDGER), proportional examples (gains 0.5-2; Fig. 4 set-up)"),
    ("ablation_teachers", "example_gain_range=0.25,0.35", "product: greedy policy (HEDGER), gentle teacher (gains 0.25-0.35)"),
    ("actor_corridor", "example_gain_range=0.5,2",
     "product: actor on HEDGER's values (policy = actor), proportional examples (gains 0.5-2; Fig. 4 set-up)"),
    ("actor_corridor", "example_gain_range=0.25,0.35",
     "product: actor on HEDGER's values (policy = actor), gentle teacher (gains 0.25-0.35)"),
    ("corridor_human_10m", "policy=greedy", "product: greedy policy (HEDGER), sloppy human's examples (Fig. 5's driver)"),
    ("corridor_human_10m", "policy=actor",
     "product: actor on HEDGER's values (policy = actor), sloppy human's examples (Fig. 5's driver)"),
)
# Experiments whose only place in the report is a product row of the reference-learner table: their
# learning curves are drawn in that section's figure, not in one of their own.
PRODUCT_ONLY = ("actor_corridor", "corridor_human_10m")
TOLERANCES = (0.01, 0.03)
LEARNER_LABELS = {"sac": "SAC (Stable-Baselines3)", "ppo": "PPO (Stable-Baselines3)", "td3": "TD3 (Stable-Baselines3)"}


def fmt_steps(x):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    return "> budget" if math.isinf(x) else "{:,.0f}".format(x)


def fmt_median(m, digits=0, fmt=None):
    """A stats.median_ci as "median [lo, hi]"; censored values as "> budget"."""
    f = fmt or (lambda v: fmt_steps(v) if digits == 0 else ("n/a" if math.isnan(v) else "%.*f" % (digits, v)))
    med, lo, hi, n = m
    if n == 0:
        return "n/a"
    if math.isnan(lo):
        return f(med)
    return "%s [%s, %s]" % (f(med), f(lo), f(hi))


def progress_summary(progresses, label):
    """Across seeds: steps to within each tolerance of the optimal controller and staying there
    (median, 95 % interval; censored seeds count as more than the budget), training episodes
    ending on a wall (in all, and until within 1 % and staying), the final evaluation, and the
    learning curve (mean over seeds at each evaluation)."""
    n = len(progresses)
    row = {"label": label, "n": n, "seeds": sorted(p["seed"] for p in progresses),
           "backend": sorted({p["backend"] for p in progresses}),
           "budget": stats.median_ci([p["budget"] for p in progresses]),
           "optimal": stats.mean_ci([p["optimal"] for p in progresses])}
    for tol in TOLERANCES:
        firsts = [results.within_from(p, tol) for p in progresses]
        row["to_%g" % tol] = stats.median_ci([math.inf if i is None else p["evaluations"][i]["training_steps"]
                                              for p, i in zip(progresses, firsts)])
        row["censored_%g" % tol] = sum(1 for i in firsts if i is None)
        row["walls_until_%g" % tol] = stats.median_ci([math.inf if i is None else p["evaluations"][i]["wall_episodes"]
                                                       for p, i in zip(progresses, firsts)])
    row["walls"] = stats.median_ci([p["evaluations"][-1]["wall_episodes"] for p in progresses])
    row["walls_any"] = sum(1 for p in progresses if p["evaluations"][-1]["wall_episodes"] > 0)
    row["final"] = stats.median_ci([p["evaluations"][-1]["mean_all"] for p in progresses])
    row["final_mean"] = stats.mean_ci([p["evaluations"][-1]["mean_all"] for p in progresses])
    row["final_all10"] = sum(1 for p in progresses if p["evaluations"][-1]["successes"] == p["evaluations"][-1]["n"])
    k = min(len(p["evaluations"]) for p in progresses)
    row["curve"] = [{"training_steps": stats.mean_ci([p["evaluations"][i]["training_steps"] for p in progresses])[0],
                     "mean_all": stats.mean_ci([p["evaluations"][i]["mean_all"] for p in progresses]),
                     "median_all": stats.median_ci([p["evaluations"][i]["mean_all"] for p in progresses]),
                     "successes": stats.mean_ci([p["evaluations"][i]["successes"] for p in progresses])}
                    for i in range(k)]
    return row


def reference_rows(variants):
    """One progress_summary per variant of a reference experiment, in the file's order."""
    rows = []
    for v, rs in variants.items():
        ps = [results.progress_of_reference(r) for r in rs]
        name = ps[0]["learner"]
        rows.append(progress_summary(ps, LEARNER_LABELS.get(name, name)))
    return rows


def product_rows(data):
    """progress_summary of the product's learner for each PRODUCT_PROGRESS whose results exist,
    and (experiment, variant, label) of those that do not."""
    rows, missing = [], []
    for exp, var, label in PRODUCT_PROGRESS:
        variants = data.get(exp, {})
        rs = variants.get(var) if var else (variants.get("") or next(iter(variants.values()), None))
        ps = [p for p in (results.progress_of_learn(r) for r in rs or []) if p is not None]
        if ps:
            row = progress_summary(ps, label)
            row["experiment"], row["variant"] = exp, var
            rows.append(row)
        else:
            missing.append((exp, var, label))
    return rows, missing


# ---- learning without examples: the sensitivity study (experiments explore_*) ----------------

def explore_variant(variant, rs):
    """One variant of an exploration experiment, pooled over its seeds: runs, successes within the
    time limit (Clopper-Pearson interval), the time to the first reward of the runs that reached it
    (mean over seeds of each seed's mean, 95 % t interval), the median over all runs (a censored run
    counts at the limit: when half or more are censored the median is only known to exceed the
    limit), the fastest run, attempts per run, and the settings the runner recorded."""
    seeds = [results.explore_seed(r) for r in rs]
    times = [t for s in seeds for t in s["times_h"]]
    succ = [ok for s in seeds for ok in s["success"]]
    k, n = sum(succ), len(succ)
    ok_times = sorted(t for t, ok in zip(times, succ) if ok)
    ordered = sorted(t if ok else math.inf for t, ok in zip(times, succ))
    median = ordered[(n - 1) // 2] if n else math.nan
    return {"variant": variant, "value": results.variant_value(variant), "n_seeds": len(seeds), "runs": n,
            "successes": k, "pooled": stats.binomial(k, n, 0.5, "two-sided"),
            "hours": stats.mean_ci([s["mean_hours_succ"] for s in seeds]),
            "hours_all": stats.mean_ci([sum(s["times_h"]) / len(s["times_h"]) for s in seeds]),
            "seed_means": [sum(s["times_h"]) / len(s["times_h"]) for s in seeds],
            "median_h": median, "min_h": ok_times[0] if ok_times else math.nan,
            "attempts": stats.mean_ci([sum(s["episodes"]) / len(s["episodes"]) for s in seeds]),
            "limit_h": seeds[0]["limit_h"], "settings": seeds[0]["settings"], "seeds": [s["seed"] for s in seeds],
            "wall_s": sum(s["wall_s"] for s in seeds)}


def explore_study(data):
    """The exploration experiments of the sensitivity study: {name: {"title", "kind", "axis", "rows":
    [explore_variant, ...] in the order of experiment.vary}} for every explore_* experiment of an
    exploration kind (explore_corridor, explore_goal, or a new task's)."""
    out = {}
    for name, variants in data.items():
        first = next(iter(variants.values()))[0]
        if not name.startswith(EXPLORE_PREFIX) or not first["kind"].startswith("explore_"):
            continue
        rows = [explore_variant(v, rs) for v, rs in variants.items()]
        axis = next(iter(variants)).split("=", 1)[0].replace("experiment.explore_", "") if rows else ""
        out[name] = {"title": first.get("title") or name, "kind": first["kind"], "axis": axis, "rows": rows}
    return out


def paper_goal(distance_m):
    """Table I's (fraction %, hours) at a start distance, or None."""
    return PAPER_TABLE1.get(float(distance_m))


# The exploration studies by kind (= task): the paper's own axis (its figure sweeps it; the
# sensitivity study's combinations sweep it too), the paper's file, the words of the report's
# headings, and the paper's (share %, hours) to hold a row against. A kind not listed here (a new
# task's study) is reported without the paper's numbers.
EXPLORE_KINDS = {
    "explore_corridor": {"task": "The corridor (Fig. 6)", "paper_axis": "omega_max_radps",
                         "paper_file": "fig6_explore_corridor", "single": " (rotation limit 1 rad/s)",
                         "sweep": " (the rotation limit swept)",
                         "paper_of_single": lambda r: (None, PAPER_FIRST_REWARD_H),
                         "paper_of_sweep": lambda r: (None, PAPER_FIRST_REWARD_H)},
    "explore_goal": {"task": "The goal task (Table I)", "paper_axis": "start_distance_m",
                     "paper_file": "table1_explore_goal", "single": " (3 m; the paper: 18.7 %, 6.54 h)",
                     "sweep": " (1, 2, 3 m)",
                     "paper_of_single": lambda r: paper_goal(r["settings"].get("start_distance_m", 3.0)),
                     "paper_of_sweep": lambda r: paper_goal(r["value"])},
}


# The sensitivity study's one-at-a-time experiments in reading order (by their axis); experiments of
# other axes follow in name order.
STUDY_ORDER = ("random", "hold_s", "rotation", "omega_clip_radps", "omega_variance", "collision", "attempt_steps",
               "restart_s", "arena_walls", "v_wall_mps", "v_mps", "goal_size_m", "start", "accel_limits", "model")


def study_groups(study, kind, sweeps):
    """[(name, group)] of one task's experiments of the study (explore_study): the sweeps of the
    paper's own axis (sweeps true) or the one-at-a-time ones, in reading order; the product's own
    (name *_product) apart."""
    axis = EXPLORE_KINDS.get(kind, {}).get("paper_axis")
    gs = [(n, g) for n, g in study.items() if g["kind"] == kind and not n.endswith("_product") and
          ((g["axis"] == axis) == sweeps)]
    return sorted(gs, key=lambda ng: (STUDY_ORDER.index(ng[1]["axis"]) if ng[1]["axis"] in STUDY_ORDER
                                      else len(STUDY_ORDER), ng[0]))


def fastest_claim(name, rows):
    """Fig. 6's "the fastest ... slightly over two hours" for a sweep of the rotation limit: the
    smallest mean time over the limits, every run of it reaching the reward; holds when that mean's
    95 % interval lies above 2 h."""
    full = [r for r in rows if r["successes"] == r["runs"] and not math.isnan(r["hours"][0])]
    if not full:
        return claim("(%s) The fastest setting needs slightly over two hours to the first reward." % name,
                     "no limit with every run reaching the reward", "-", None, 0)
    best = min(full, key=lambda r: r["hours"][0])
    m, hw, n = best["hours"]
    return claim("(%s) The fastest setting needs slightly over two hours to the first reward." % name,
                 "fastest: limit %s rad/s, %s h (fastest single run %.3g h)" % (best["value"], fmt_ci(m, hw, 3),
                                                                              best["min_h"]),
                 "mean with 95 % CI above 2 h?", None if math.isnan(hw) else m - hw > PAPER_FIRST_REWARD_H, n)


def first_reward_of_session(r):
    """A learn result's first training run that reached the goal: (run index from 1, driving hours
    until it ended, reached). A session that never reached it gives (None, its whole training, False)."""
    dt = r["dt_s"]
    steps = 0
    train = [x for x in r["learning"]["runs"] if x["kind"] == "train" and x["outcome"] != "aborted"]
    for i, x in enumerate(train):
        steps += x["steps"]
        if x["outcome"] == "goal":
            return i + 1, steps * dt / 3600.0, True
    return None, steps * dt / 3600.0, False


def learner_without_examples(variants):
    """Per variant of a learn experiment without phase one: the first training run that reached the
    goal, the driving until then, the final block, the training driving."""
    rows = []
    for v, rs in variants.items():
        firsts = [first_reward_of_session(r) for r in rs]
        seeds = [results.learn_seed(r) for r in rs]
        rows.append({"variant": v, "n": len(rs), "reached": sum(1 for f in firsts if f[2]),
                     "first_run": stats.mean_ci([f[0] for f in firsts if f[2]]),
                     "first_hours": stats.mean_ci([f[1] for f in firsts if f[2]]),
                     "final_all": stats.mean_ci([s["final"]["mean_all"] for s in seeds]),
                     "final_succ": stats.mean_ci([s["final"]["successes"] for s in seeds]),
                     "final_by_seed": {s["seed"]: s["final"]["mean_all"] for s in seeds},
                     "all10_blocks": stats.mean_ci([sum(1 for b in s["blocks"] if b["successes"] == b["n"])
                                                    for s in seeds]),
                     "training_hours": stats.mean_ci([s["training_hours"] for s in seeds]),
                     "step_limit": seeds[0]["step_limit"], "runs": seeds[0]["phase_two_runs"]})
    return rows
