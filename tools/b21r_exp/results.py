# SPDX-License-Identifier: MIT
"""Result files of b21r-experiment and the per-seed numbers the figures and claims use.

Layout: <out>/results/<experiment>/<variant>/seed-<n>.json (variant "default" when the experiment
has no sweep axis). Every number here counts failures: an evaluation run that did not reach the
goal counts at the step limit in `mean_all`, beside `mean_succ`, the mean over successful runs."""
import json
import math
import os
import re

FORMAT = "b21r-experiment-result/1"
SOURCES = ("example", "joystick", "advisor", "greedy", "exploration")


def variant_dir(variant):
    return (variant or "default").replace("/", "_")


def result_path(out, experiment, variant, seed):
    return os.path.join(out, "results", experiment, variant_dir(variant), "seed-%d.json" % seed)


def read_result(path):
    """The parsed result, or None when the file is missing, incomplete or of another format."""
    try:
        with open(path) as f:
            d = json.load(f)
    except (OSError, ValueError):
        return None
    return d if d.get("format") == FORMAT else None


def vary_order(configs_dir, experiment):
    """The variants of experiment.vary in the order its file lists them (the first is the baseline
    of comparisons), or [] when the file or the key is missing."""
    try:
        with open(os.path.join(configs_dir, experiment + ".conf")) as f:
            for line in f:
                m = re.match(r"\s*experiment\.vary\s*=\s*([^#]*)", line)
                if m and "=" in m.group(1):
                    key, values = m.group(1).strip().strip('"').split("=", 1)
                    return ["%s=%s" % (key.strip(), v.strip()) for v in values.split("|")]
    except OSError:
        pass
    return []


def load(out, configs_dir=None):
    """{experiment: {variant: [result, ...] sorted by seed}} of every result under out. Variants
    follow the order of experiment.vary in configs_dir (else the order they were run with)."""
    root = os.path.join(out, "results")
    found = {}
    if not os.path.isdir(root):
        return found
    for exp in sorted(os.listdir(root)):
        for var in sorted(os.listdir(os.path.join(root, exp))):
            d = os.path.join(root, exp, var)
            if not os.path.isdir(d):
                continue
            rs = [read_result(os.path.join(d, f)) for f in os.listdir(d) if f.startswith("seed-") and f.endswith(".json")]
            rs = sorted((r for r in rs if r is not None), key=lambda r: r["seed"])
            if rs:
                found.setdefault(exp, {})[rs[0]["variant"]] = rs
    ordered = {}
    for e, v in found.items():
        order = vary_order(configs_dir, e) if configs_dir else []
        key = (lambda kv: order.index(kv[0]) if kv[0] in order else len(order) + kv[1][0].get("variant_index", 0))
        ordered[e] = dict(sorted(v.items(), key=key))
    return ordered


def nan_mean(v):
    v = [x for x in v if x is not None and not math.isnan(x)]
    return sum(v) / len(v) if v else math.nan


def block_numbers(block):
    """mean_all (failures at the step limit), mean_succ (successful runs only), successes, n."""
    steps = block["steps"]
    succ = [s for s, ok in zip(steps, block["success"]) if ok]
    return {"mean_all": sum(steps) / len(steps), "mean_succ": nan_mean(succ), "successes": len(succ),
            "n": len(steps)}


def learn_seed(r):
    """Per-seed summary of a learn result."""
    L = r["learning"]
    dt = r["dt_s"]
    limit = r["step_limit"]
    blocks = []
    for b in L["blocks"]:
        x = block_numbers(b)
        x.update(training_runs=b["training_runs"], phase=b["phase"], store_fill=b["store_fill"],
                 training_hours=b["training_time_s"] / 3600.0)
        blocks.append(x)
    train = [x for x in L["runs"] if x["kind"] == "train" and x["outcome"] != "aborted"]
    p1 = [x for x in train if x["phase"] == 1]
    p2 = [x for x in train if x["phase"] == 2]
    p1_goal = [x["steps"] for x in p1 if x["outcome"] == "goal"]
    p1_all = [x["steps"] if x["outcome"] == "goal" else limit for x in p1]
    refs = {k: block_numbers(v) for k, v in r.get("references", {}).items()}
    ref_steps = {k: v["steps"] for k, v in r.get("references", {}).items()}
    totals = L["totals"]

    def source_fraction(runs):
        tot = {s: sum(x["sources"].get(s, 0) for x in runs) for s in SOURCES}
        n = sum(tot.values())
        return {s: (tot[s] / n if n else math.nan) for s in SOURCES}, n

    p2_frac, p2_steps = source_fraction(p2)
    switch = L.get("phase_switch_after_training_runs")
    first_success = next((b["training_runs"] for b in blocks if b["successes"] > 0), None)
    p1_blocks = [b for b in blocks if b["phase"] == 1]
    p2_blocks = [b for b in blocks if b["phase"] == 2]
    return {
        "seed": r["seed"],
        "blocks": blocks,
        "final": blocks[-1] if blocks else None,
        "last_phase_one": p1_blocks[-1] if p1_blocks else None,
        "first_phase_two": p2_blocks[0] if p2_blocks else None,
        "phase_two_blocks": p2_blocks,
        "final_steps": L["blocks"][-1]["steps"] if L["blocks"] else None,
        "best_example": min(p1_goal) if p1_goal else math.nan,
        "mean_example": sum(p1_all) / len(p1_all) if p1_all else math.nan,
        "phase_one_runs": len(p1),
        "phase_two_runs": len(p2),
        "switch_after": switch,
        "first_success_after": first_success,
        "refs": refs,
        "ref_steps": ref_steps,
        "training_hours": totals["training_time_s"] / 3600.0,
        "eval_hours": totals["eval_time_s"] / 3600.0,
        "training_hours_to_switch": (sum(x["steps"] for x in p1) * dt / 3600.0),
        "phase_two_sources": p2_frac,
        "phase_two_steps": p2_steps,
        "store_fill": totals["store_fill"],
        "digest": L.get("phase_one_data_digest"),
        "wall_s": L["wall_time_s"] + sum(v.get("wall_time_s", 0.0) for v in r.get("references", {}).values()),
        "step_limit": limit,
    }


def explore_seed(r):
    """Per-seed summary of an exploration result: its runs' times (to the first reward, or the
    limit when censored), successes, attempts, and the settings the runner recorded."""
    runs = r["explore"]["runs"]
    ok = [x["time_s"] for x in runs if x["success"]]
    return {"seed": r["seed"], "runs": len(runs), "successes": len(ok), "fraction": len(ok) / len(runs),
            "mean_hours_succ": (sum(ok) / len(ok) / 3600.0) if ok else math.nan,
            "times_h": [x["time_s"] / 3600.0 for x in runs], "success": [x["success"] for x in runs],
            "episodes": [x["episodes"] for x in runs],
            "driving_h": [x.get("driving_s", x["time_s"]) / 3600.0 for x in runs],
            "settings": {k: v for k, v in r["explore"].items() if k not in ("runs", "wall_time_s")},
            "wall_s": r["explore"]["wall_time_s"], "limit_h": r["explore"]["time_limit_s"] / 3600.0}


def variant_value(variant):
    """'key=value' -> value (for axes); '' -> ''."""
    return variant.split("=", 1)[1] if "=" in variant else variant


# ---- progress against training steps (reference learners and the product's learner alike) ------


def _evaluation(training_steps, training_episodes, wall_episodes, steps, success):
    return {"training_steps": int(training_steps), "training_episodes": int(training_episodes),
            "wall_episodes": int(wall_episodes), "mean_all": sum(steps) / len(steps),
            "successes": sum(1 for s in success if s), "n": len(steps)}


def progress_of_reference(r):
    """The evaluations of a reference learner's result (b21r_exp.reference) against training
    steps, and its optimal controller from the same poses."""
    R = r["reference"]
    evals = [_evaluation(e["training_steps"], e["training_episodes"], e["wall_episodes"], e["steps"], e["success"])
             for e in R["evaluations"]]
    return {"seed": r["seed"], "learner": R["algorithm"], "backend": R["backend"], "evaluations": evals,
            "optimal": sum(R["optimal"]["steps"]) / len(R["optimal"]["steps"]), "budget": R["train_steps"],
            "step_limit": r["step_limit"]}


def progress_of_learn(r):
    """The evaluation blocks of the product's learner (a b21r-experiment learn result) against
    the training steps of both phases, examples included (evaluation runs are not counted), and
    the training runs so far that ended on a wall; None when the result has no optimal
    reference."""
    L = r["learning"]
    opt = r.get("references", {}).get("optimal")
    if opt is None or not L["blocks"]:
        return None
    train = sorted((x for x in L["runs"] if x["kind"] == "train"), key=lambda x: x["training_index"])
    evals = []
    for b in L["blocks"]:
        done = train[: b["training_runs"]]
        steps = b.get("training_steps", sum(x["steps"] for x in done))
        walls = sum(1 for x in done if x["outcome"] == "collision")
        evals.append(_evaluation(steps, b["training_runs"], walls, b["steps"], b["success"]))
    return {"seed": r["seed"], "learner": "hedger", "backend": "ode", "evaluations": evals,
            "optimal": sum(opt["steps"]) / len(opt["steps"]), "budget": L["totals"]["training_steps"],
            "step_limit": r["step_limit"]}


def within_from(progress, tolerance):
    """The first evaluation from which every later one (itself included) is within `tolerance`
    (0.01 = 1 %) of the optimal controller's mean steps from the same poses (both with failures at
    the step limit): its index, or None when the final evaluation is not (censored)."""
    bound = (1.0 + tolerance) * progress["optimal"]
    first = None
    for i, e in enumerate(progress["evaluations"]):
        if e["mean_all"] <= bound + 1e-9:
            if first is None:
                first = i
        else:
            first = None
    return first
