# SPDX-License-Identifier: MIT
"""Paper-style figures from the result files (matplotlib, PNG), each with its caption under the
plot; the captions are also returned for the report."""
import math
import os
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from b21r_exp import analysis, results, stats  # noqa: E402

LEARN_FIGS = {
    "fig4_corridor_examples": "fig4_corridor_examples.png",
    "fig5_corridor_human": "fig5_corridor_human.png",
}
COLOURS = {"example": "#1f77b4", "joystick": "#9467bd", "advisor": "#ff7f0e", "greedy": "#2ca02c",
           "exploration": "#d62728"}


def _caption(fig, text):
    fig.text(0.01, 0.005, "\n".join(textwrap.wrap(text, 140)), fontsize=7.5, va="bottom", ha="left")


def _seeds_text(S):
    s = S["seed_list"]
    return "seeds %d-%d" % (min(s), max(s)) if s == list(range(min(s), max(s) + 1)) else "seeds %s" % s


def _hline(ax, value, label, style, colour):
    m, hw, n = value
    if n == 0 or math.isnan(m):
        return
    ax.axhline(m, linestyle=style, color=colour, linewidth=1.2, label=label)
    if not math.isnan(hw):
        ax.axhspan(m - hw, m + hw, color=colour, alpha=0.08)


def learn_figure(S, title, path, command, successes_only=False):
    """Steps to the goal per evaluation block (mean over seeds, 95 % CI), comparators, phase switch;
    successes out of 10 per block; who drove the training steps of phase two."""
    curve = S["curve"]
    x = [c["training_runs"] for c in curve]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 7.2), gridspec_kw={"height_ratios": [3, 1.2]}, sharex=True)
    key = "mean_succ" if successes_only else "mean_all"
    m = [c[key][0] for c in curve]
    e = [0 if math.isnan(c[key][1]) else c[key][1] for c in curve]
    ax.errorbar(x, m, yerr=e, marker="o", color="black", capsize=3, linewidth=1.4,
                label="learned policy (%s)" % ("successful runs only" if successes_only else "failures at the step limit"))
    if not successes_only:
        ms = [c["mean_succ"][0] for c in curve]
        ax.plot(x, ms, marker=".", linestyle=":", color="grey", label="learned policy, successful runs only")
    _hline(ax, S["refs"].get("optimal", (math.nan, math.nan, 0)), "optimal (hand-tuned, same poses)", "--", "#2ca02c")
    _hline(ax, S["refs"].get("example", (math.nan, math.nan, 0)), "example policy, nominal gain (same poses)", "-.", "#1f77b4")
    best = analysis.best_example_ref(S)
    if best is not None and best != "example":
        _hline(ax, S["refs"][best], "%s (the best gain evaluated, same poses)" % analysis.ref_label(best),
               (0, (1, 1)), "#17becf")
    _hline(ax, S["best_example"], "best example (shortest phase-one run)", ":", "#9467bd")
    _hline(ax, S["mean_example"], "mean phase-one run", (0, (5, 2, 1, 2)), "#8c564b")
    sm, _, sn = S["switch_after"]
    if sn > 0 and not math.isnan(sm):
        for a in (ax, ax2):
            a.axvline(sm, color="red", linewidth=0.8, linestyle="--")
        ax.text(sm, ax.get_ylim()[1], " phase two ", color="red", va="top", fontsize=8)
    ax.set_ylabel("steps to the goal")
    ax.set_ylim(bottom=0)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper right")
    ax.grid(alpha=0.3)
    s = [c["successes"][0] for c in curve]
    se = [0 if math.isnan(c["successes"][1]) else c["successes"][1] for c in curve]
    ax2.errorbar(x, s, yerr=se, marker="s", color="black", capsize=3)
    ax2.set_ylim(-0.5, 10.5)
    ax2.set_ylabel("successes / 10")
    ax2.set_xlabel("training runs")
    ax2.grid(alpha=0.3)
    src = S["phase_two_sources"]
    src_text = ", ".join("%s %.0f %%" % (k, 100 * v[0]) for k, v in src.items() if not math.isnan(v[0]) and v[0] > 0)
    cap = ("%s. Mean over %d seeds (%s) of each evaluation block (learning off, the same %s start poses every "
           "block) with 95 %% confidence intervals across seeds; a run that does not reach the goal counts at the "
           "step limit (%d). Horizontal lines: the comparators (bands: 95 %% CI). Phase-two training steps were "
           "driven by: %s. Made by: %s" % (title, S["n"], _seeds_text(S), "10", S["step_limit"],
                                            src_text or "n/a", command))
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


def obstacle_figures(S, title, fig_dir, command):
    p9 = os.path.join(fig_dir, "fig9_obstacles_successes.png")
    curve = S["curve"]
    x = [c["training_runs"] for c in curve]
    fig, ax = plt.subplots(figsize=(8, 4.6))
    s = [c["successes"][0] for c in curve]
    se = [0 if math.isnan(c["successes"][1]) else c["successes"][1] for c in curve]
    ax.errorbar(x, s, yerr=se, marker="s", color="black", capsize=3, label="learned policy")
    _hline(ax, stats.mean_ci([s["refs"]["optimal"]["successes"] for s in S["seeds"] if "optimal" in s["refs"]]),
           "optimal controller (same poses)", "--", "#2ca02c")
    sm, _, sn = S["switch_after"]
    if sn > 0:
        ax.axvline(sm, color="red", linewidth=0.8, linestyle="--")
    ax.set_ylim(-0.5, 10.5)
    ax.set_xlabel("training runs")
    ax.set_ylabel("successful runs (out of 10)")
    ax.set_title(title + ": successes", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    cap9 = ("Obstacle avoidance (paper Fig. 9): evaluation runs out of 10 that reached the goal, mean over %d seeds "
            "(%s) with 95 %% CI; red: phase switch. Made by: %s" % (S["n"], _seeds_text(S), command))
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    _caption(fig, cap9)
    fig.savefig(p9, dpi=110)
    plt.close(fig)
    p10 = os.path.join(fig_dir, "fig10_obstacles_steps.png")
    cap10 = learn_figure(S, title + ": steps of the successful runs (Fig. 10)", p10, command, successes_only=True)
    return [(p9, cap9), (p10, cap10)]


def explore_corridor_figure(rows, path, command):
    fig, ax = plt.subplots(figsize=(8, 4.6))
    xs = [r["limit"] for r in rows]
    for r in rows:
        ax.scatter([r["limit"]] * len(r["times_h"]), r["times_h"], s=6, color="grey", alpha=0.4)
    m = [r["hours"][0] for r in rows]
    e = [0 if math.isnan(r["hours"][1]) else r["hours"][1] for r in rows]
    ax.errorbar(xs, m, yerr=e, marker="o", color="black", capsize=3, label="mean over seeds (95 % CI)")
    ax.axhline(analysis.PAPER_HOURS, color="#d62728", linestyle="--", label="paper: fastest slightly over 2 h")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rotation velocity limit [rad/s]")
    ax.set_ylabel("time to the first reward [h]")
    ax.set_title("Random exploration in the 10 m corridor (paper Fig. 6)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    n_runs = sum(r["runs"] for r in rows)
    cap = ("Simulated time until the first reward with rotation drawn uniformly from [-limit, limit] every step "
           "(idealised kinematic model, the task's speed policy, start on the centre line 1 m from the start wall, "
           "heading uniform towards the goal; a collision restarts the attempt, the clock runs on). Dots: single "
           "runs (%d in all); black: mean over seeds (%s) with 95 %% CI. Made by: %s" % (
               n_runs, "seeds %s" % rows[0]["seeds"] if rows else "-", command))
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


def ablation_figure(name, variants, title, path, command):
    fig, ax = plt.subplots(figsize=(8, 4.8))
    summ = {v: analysis.learn_summary(rs) for v, rs in variants.items()}
    for i, (v, S) in enumerate(summ.items()):
        x = [c["training_runs"] for c in S["curve"]]
        m = [c["mean_all"][0] for c in S["curve"]]
        e = [0 if math.isnan(c["mean_all"][1]) else c["mean_all"][1] for c in S["curve"]]
        ax.errorbar([xi + 0.25 * i for xi in x], m, yerr=e, marker="o", capsize=2, label=v or "default")
    first = next(iter(summ.values()))
    _hline(ax, first["refs"].get("optimal", (math.nan, math.nan, 0)), "optimal (same poses)", "--", "black")
    ax.set_xlabel("training runs")
    ax.set_ylabel("steps to the goal")
    ax.set_ylim(bottom=0)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    cap = ("%s: mean steps per evaluation block over %d seeds (%s) with 95 %% CI, failures at the step limit. "
           "Made by: %s" % (title, first["n"], _seeds_text(first), command))
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


def reference_figure(rows, title, path, command):
    """Learning curves against training steps: each reference learner (and the product's learner,
    where its results exist), the median evaluation over seeds with the 95 % interval of the
    median, the optimal controller and 1 % / 3 % above it; the lower panel zooms in on the optimal
    controller."""
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 7.6), gridspec_kw={"height_ratios": [1.3, 1]}, sharex=True)
    styles = ["-", "--", "-.", ":"]
    for i, r in enumerate(rows):
        x = [c["training_steps"] for c in r["curve"]]
        med = [c["median_all"] for c in r["curve"]]
        product = r["label"].startswith("product")
        for a in (ax, ax2):
            line, = a.plot(x, [m[0] for m in med], linestyle=styles[i % len(styles)], marker="o" if product else None,
                           markersize=3, linewidth=1.4, label="%s (%d seeds)" % (r["label"], r["n"]))
            if all(not math.isnan(m[1]) for m in med):
                a.fill_between(x, [m[1] for m in med], [m[2] for m in med], color=line.get_color(), alpha=0.12)
    opt = rows[0]["optimal"] if rows else (math.nan, math.nan, 0)
    for a in (ax, ax2):
        if not math.isnan(opt[0]):
            a.axhline(opt[0], color="black", linewidth=1.2, label="optimal controller (same poses)")
            for tol, style in ((0.01, (0, (1, 1))), (0.03, (0, (4, 2)))):
                a.axhline(opt[0] * (1 + tol), color="grey", linewidth=0.8, linestyle=style,
                          label="%d %% above optimal" % round(100 * tol))
        a.grid(alpha=0.3)
    ax.set_ylim(0, 1050)
    ax.set_ylabel("steps to the goal")
    ax.set_title("\n".join(textwrap.wrap(title, 90)), fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    if not math.isnan(opt[0]):
        ax2.set_ylim(opt[0] * 0.97, opt[0] * 1.25)
    ax2.set_ylabel("steps (zoom)")
    ax2.set_xlabel("training steps (environment steps of training; evaluation runs not counted)")
    cap = ("%s: median over seeds of each evaluation's mean steps (the deterministic policy from the task's 10 "
           "evaluation poses, a run that does not reach the goal counted at the step limit) against the training steps "
           "so far; bands: the 95 %% interval of the median (order statistics; drawn from 6 seeds on). The product's "
           "learner counts the training steps of both phases, its examples included. Black: the optimal controller "
           "from the same poses; grey: 1 %% and 3 %% above it. Made by: %s" % (title, command))
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


STUDY_COMMAND = "tools/b21r_experiments.py run 'explore_*' figures"


def _label(name, row):
    return "%s: %s" % (name[len(analysis.EXPLORE_PREFIX):], row["value"])


def _err(values):
    return [0 if math.isnan(v) else v for v in values]


def study_rows_figure(groups, path, title, paper_h, paper_label, fraction=False):
    """One dot per variant (rows grouped by experiment): the time to the first reward of the runs
    that reached it (log scale, 95 % CI) and, with fraction, the share of runs that reached it."""
    rows = [(name, r) for name, g in groups for r in g["rows"]]
    if not rows:
        return None
    ncols = 2 if fraction else 1
    fig, axes = plt.subplots(1, ncols, figsize=(9.5 if fraction else 8, 0.24 * len(rows) + 1.9), sharey=True,
                             squeeze=False)
    y = list(range(len(rows)))[::-1]
    ax = axes[0][ncols - 1]
    hours = [r["hours"] for _, r in rows]
    ok = [i for i, h in enumerate(hours) if not math.isnan(h[0])]
    ax.errorbar([hours[i][0] for i in ok], [y[i] for i in ok], xerr=_err([hours[i][1] for i in ok]), fmt="o",
                color="black", capsize=2, markersize=3)
    if paper_h:
        ax.axvline(paper_h, color="#d62728", linestyle="--", label=paper_label)
    ax.set_xscale("log")
    ax.set_xlabel("time to the first reward [h] (runs that reached it)")
    ax.grid(alpha=0.3, which="both", axis="x")
    if paper_h:
        ax.legend(fontsize=7, loc="lower right")
    if fraction:
        af = axes[0][0]
        fr = [100 * r["pooled"]["fraction"] for _, r in rows]
        lo = [100 * r["pooled"]["lo"] for _, r in rows]
        hi = [100 * r["pooled"]["hi"] for _, r in rows]
        af.errorbar(fr, y, xerr=[[f - a for f, a in zip(fr, lo)], [b - f for f, b in zip(fr, hi)]], fmt="s",
                    color="black", capsize=2, markersize=3)
        if paper_h:
            af.axvline(analysis.PAPER_TABLE1[3.0][0], color="#d62728", linestyle="--", label="paper (3 m): 18.7 %")
            af.legend(fontsize=7, loc="lower right")
        af.set_xlim(-2, 102)
        af.set_xlabel("runs that reached the goal within the limit [%]")
        af.grid(alpha=0.3, axis="x")
    axes[0][0].set_yticks(y)
    axes[0][0].set_yticklabels([_label(n, r) for n, r in rows], fontsize=7)
    fig.suptitle(title, fontsize=10)
    cap = ("%s. Each row changes one assumption of the paper's study as the paper's figure reads it (mean over "
           "the seeds of each seed's mean, 95 %% CI; shares pooled over seeds with Clopper-Pearson 95 %% intervals; "
           "a row without a dot: no run reached the reward within the limit). Made by: %s" % (title, STUDY_COMMAND))
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


def study_sweep_figure(groups, path, title, axis_label, paper, log_x, fraction=False):
    """Each combination's sweep of the paper's own axis (rotation limit, start distance) as one line,
    with the paper's numbers: the time to the first reward, or the share that reached it."""
    if not groups:
        return None
    fig, ax = plt.subplots(figsize=(8, 4.8))
    for i, (name, g) in enumerate(groups):
        xs = [float(r["value"]) for r in g["rows"]]
        if fraction:
            ys = [100 * r["pooled"]["fraction"] for r in g["rows"]]
            lo = [100 * r["pooled"]["lo"] for r in g["rows"]]
            hi = [100 * r["pooled"]["hi"] for r in g["rows"]]
            err = [[a - b for a, b in zip(ys, lo)], [b - a for a, b in zip(ys, hi)]]
        else:
            ys = [r["hours"][0] for r in g["rows"]]
            err = _err([r["hours"][1] for r in g["rows"]])
        ax.errorbar([x * (1 + 0.03 * i) for x in xs], ys, yerr=err, marker="o", capsize=2, label=g["title"])
    if fraction:
        ax.plot(sorted(paper), [paper[d][0] for d in sorted(paper)], "D--", color="#d62728", label="paper (Table I)")
        ax.set_ylabel("runs that reached the goal within the limit [%]")
        ax.set_ylim(-2, 102)
    else:
        ax.axhline(paper, color="#d62728", linestyle="--", label="paper: fastest slightly over 2 h")
        ax.set_yscale("log")
        ax.set_ylabel("time to the first reward [h] (runs that reached it)")
    if log_x:
        ax.set_xscale("log")
    ax.set_xlabel(axis_label)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=6.5)
    cap = ("%s: mean over seeds with 95 %% CI%s. Made by: %s" % (
        title, " (shares pooled over seeds, Clopper-Pearson)" if fraction else "", STUDY_COMMAND))
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    _caption(fig, cap)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return cap


def explore_study_figures(data, fig_dir):
    """The sensitivity study's figures, per task (the experiment's kind): the one-at-a-time rows
    (<kind>_sensitivity.png) and the sweeps of the paper's own axis under combinations
    (<kind>_combinations.png). Returns [(path, caption)]."""
    study = analysis.explore_study(data)
    out = []
    for kind in sorted({g["kind"] for g in study.values()}):
        info = analysis.EXPLORE_KINDS.get(kind, {"task": kind, "paper_axis": None})
        single = analysis.study_groups(study, kind, False)
        sweeps = analysis.study_groups(study, kind, True)
        groups = single + sweeps
        p = os.path.join(fig_dir, "%s_sensitivity.png" % kind)
        q = os.path.join(fig_dir, "%s_combinations.png" % kind)
        title = "%s without examples: one assumption at a time" % info["task"]
        if kind == "explore_corridor":
            c = study_rows_figure(single, p, title + " (limit 1 rad/s)", analysis.PAPER_FIRST_REWARD_H,
                                  "paper: fastest slightly over 2 h")
            d = study_sweep_figure(sweeps, q, "Fig. 6 under combinations of assumptions", "rotation velocity limit [rad/s]",
                                   analysis.PAPER_FIRST_REWARD_H, True)
        elif kind == "explore_goal":
            c = study_rows_figure(single, p, title + " (3 m)", analysis.PAPER_TABLE1[3.0][1], "paper (3 m): 6.54 h",
                                  fraction=True)
            d = study_sweep_figure(sweeps, q, "Table I under combinations of assumptions", "start distance [m]",
                                   analysis.PAPER_TABLE1, False, fraction=True)
        else:
            c = study_rows_figure(groups, p, title, None, None, fraction=True)
            d = None
        out += [(x, y) for x, y in ((p, c), (q, d)) if y is not None]
    return out


def command_for(name):
    return "tools/b21r_experiments.py run figures %s" % name


def make_all(out, fig_dir, configs_dir, captions=None, only=None):
    """Writes every figure the results allow (only: the experiments of these names); returns their
    paths. captions (dict) gets {file name: caption}."""
    os.makedirs(fig_dir, exist_ok=True)
    data = results.load(out, configs_dir)
    made = []
    caps = captions if captions is not None else {}
    for name, variants in data.items():
        if only is not None and name not in only:
            continue
        first = next(iter(variants.values()))
        title = first[0].get("title") or name
        kind = first[0]["kind"]
        cmd = command_for(name)
        if kind == "learn" and name in analysis.PRODUCT_ONLY:
            continue
        if kind == "learn" and name.startswith(("ablation_", analysis.EXPLORE_PREFIX)):
            p = os.path.join(fig_dir, name + ".png")
            caps[os.path.basename(p)] = ablation_figure(name, variants, title, p, cmd)
            made.append(p)
        elif kind == "learn":
            S = analysis.learn_summary(next(iter(variants.values())))
            if first[0]["task"] == "obstacles":
                for p, c in obstacle_figures(S, title, fig_dir, cmd):
                    caps[os.path.basename(p)] = c
                    made.append(p)
            else:
                p = os.path.join(fig_dir, LEARN_FIGS.get(name, name + ".png"))
                caps[os.path.basename(p)] = learn_figure(S, title, p, cmd)
                made.append(p)
        elif kind == "reference":
            rows = analysis.reference_rows(variants)
            if first[0]["task"] == "corridor":
                rows += analysis.product_rows(data)[0]
            p = os.path.join(fig_dir, name + ".png")
            caps[os.path.basename(p)] = reference_figure(rows, title, p, cmd)
            made.append(p)
        elif kind == "explore_corridor" and name == "fig6_explore_corridor":
            p = os.path.join(fig_dir, "fig6_explore_corridor.png")
            caps[os.path.basename(p)] = explore_corridor_figure(analysis.explore_corridor_summary(variants), p, cmd)
            made.append(p)
    study_data = data if only is None else {n: v for n, v in data.items() if n in only}
    for p, c in explore_study_figures(study_data, fig_dir):
        caps[os.path.basename(p)] = c
        made.append(p)
    return made
