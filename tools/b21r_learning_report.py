#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_learning_report: the learning curve and the summary of a two-phase learning session.

Reads the controller's LCM event log of the learning run (B21R_EVAL, B21R_EXPERIENCE) and,
optionally, the logs of reference evaluations (mode = evaluate with evaluate_policy = optimal /
example), and writes into OUTDIR:
  learning_curve.png  mean steps to the goal with 95 % confidence intervals per evaluation block
                      (phase one and phase two marked), the "best example" line (shortest phase-one
                      training run) and the "optimal" line (the hand-tuned reference controller),
                      as the paper's Fig. 4; successes out of 10 below
  summary.json        every number of the plot, the claims and who drove every run, machine-readable
  summary.txt         the same for people: each of the paper's claims with yes/no and its numbers
Every comparison is paired over the evaluation poses (the same 10 poses for every policy, this
seed); a run that does not reach the goal counts at the step limit; 95 % Student-t intervals.
One seed shows one session: the claims over 10 seeds are in docs/RESULTS.md.
Usage:
  b21r_learning_report.py --log LEARN.lcmlog [--optimal OPT.lcmlog] [--example EX.lcmlog]
                          [--example-gain GAIN=EX.lcmlog ...] [--corridor-length M] --out OUTDIR
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from b21r_log import read_log, runs_from_experiences  # noqa: E402

# Student-t quantiles for 9 degrees of freedom (10 poses): 0.95 one-sided, 0.975 two-sided.
T95_ONE_SIDED_DF9 = 1.833
T975_DF9 = 2.262
SOURCE_NAMES = {0: "example", 1: "joystick", 2: "greedy", 3: "exploration", 4: "advisor"}  # experience_t.SOURCE_*
LEARNER_SOURCES = ("greedy", "exploration")


def paired(a, b):
    """Paired over poses: mean of a - b, its 95 % half-width and t (df = n - 1, meant for n = 10)."""
    d = [x - y for x, y in zip(a, b)]
    n = len(d)
    m = sum(d) / n
    sd = math.sqrt(sum((x - m) ** 2 for x in d) / (n - 1)) if n > 1 else 0.0
    se = sd / math.sqrt(n) if n > 0 else 0.0
    t = m / se if se > 0 else (math.inf if m > 0 else (-math.inf if m < 0 else 0.0))
    return m, T975_DF9 * se, t


def mean_all(block):
    """Mean steps over every pose, failures at the step limit."""
    n = block["n_starts"]
    return sum(block["steps"][:n]) / n


def claims(blocks, optimal, examples, train):
    """The paper's claims for one session, each (claim, holds, numbers). examples: {gain: block}."""
    out = []
    p1 = [b for b in blocks if b["phase"] == 1]
    p2 = [b for b in blocks if b["phase"] == 2]
    final = blocks[-1]
    if p1 and len(blocks) > 1:
        # Descriptive for one session: a single failed pose (at the step limit) in the first block
        # makes any paired test over poses meaningless; the 10-seed test is in docs/RESULTS.md.
        a, b = mean_all(blocks[0]), mean_all(p1[-1])
        out.append(("the curve falls: after phase one fewer steps (failures at the limit) and no fewer poses reached "
                    "than in the first block (descriptive)",
                    b < a and p1[-1]["successes"] >= blocks[0]["successes"],
                    "%.1f steps (%d/%d reached) -> %.1f steps (%d/%d)" % (
                        a, blocks[0]["successes"], blocks[0]["n_starts"], b, p1[-1]["successes"], p1[-1]["n_starts"])))
    if examples and p1:
        best_gain = min(examples, key=lambda g: mean_all(examples[g]))
        best = examples[best_gain]
        m, h, t = paired(p1[-1]["steps"], best["steps"])
        out.append(("after phase one, at least as good as the example policy at its best gain (%s, %.1f steps), "
                    "same poses: not significantly worse" % (best_gain, mean_all(best)),
                    t <= T95_ONE_SIDED_DF9, "%+.1f ± %.1f steps (t = %.2f)" % (m, h, t)))
        out.append(("after phase one, significantly better than the example policy at its best gain",
                    t < -T95_ONE_SIDED_DF9, "%+.1f ± %.1f steps (t = %.2f)" % (m, h, t)))
    if optimal is not None and p2:
        m, h, t = paired(final["steps"], optimal["steps"])
        out.append(("after phase two, not significantly worse than the optimal controller (%.1f steps)" %
                    mean_all(optimal), t <= T95_ONE_SIDED_DF9, "%+.1f ± %.1f steps (t = %.2f)" % (m, h, t)))
    if p1 and p2:
        m, h, t = paired(final["steps"], p1[-1]["steps"])
        out.append(("phase two keeps the policy: final block not significantly worse than after phase one",
                    t <= T95_ONE_SIDED_DF9, "%+.1f ± %.1f steps (t = %.2f)" % (m, h, t)))
    if p2:
        reached = sum(1 for b in p2 if b["successes"] == b["n_starts"])
        out.append(("every pose reached in every phase-two block", reached == len(p2),
                    "%d of %d blocks" % (reached, len(p2))))
    p2_runs = [r for r in train if r["phase"] == 2]
    if p2_runs:
        total = sum(sum(r["sources"].values()) for r in p2_runs)
        learner = sum(r["sources"].get(s, 0) for r in p2_runs for s in LEARNER_SOURCES)
        share = 100.0 * learner / total if total else 0.0
        out.append(("phase two is driven by the learned policy: at least 95 % of its training steps greedy or "
                    "exploration", share >= 95.0, "%.1f %% of %d steps" % (share, total)))
    return out


def eval_blocks(path):
    blocks = []
    for _, _, e in read_log(path, {"B21R_EVAL"}):
        n = e.n_starts
        blocks.append({
            "block": e.block, "training_runs": e.training_runs, "phase": e.phase,
            "n_starts": n, "steps": list(e.steps[:n]), "success": [bool(s) for s in e.success[:n]],
            "successes": e.successes, "mean_steps": e.mean_steps, "ci95_halfwidth": e.ci95_halfwidth,
        })
    return blocks


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log", required=True, help="event log of the learning run")
    ap.add_argument("--optimal", help="event log of the optimal controller's evaluation")
    ap.add_argument("--example", help="event log of the example policy's evaluation (nominal gain)")
    ap.add_argument("--example-gain", action="append", default=[], metavar="GAIN=LOG",
                    help="event log of the example policy evaluated at this gain (evaluate_example_gain)")
    ap.add_argument("--corridor-length", type=float, default=10.0,
                    help="corridor length [m], for the kinematic bound on the optimal controller")
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="Corridor following, emulated B21r")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    blocks = eval_blocks(args.log)
    if not blocks:
        sys.exit("b21r_learning_report: no B21R_EVAL in %s" % args.log)
    exps = [m for _, _, m in read_log(args.log, {"B21R_EXPERIENCE"})]
    runs = runs_from_experiences(exps)
    for r in runs:
        r["sources"] = {SOURCE_NAMES.get(k, str(k)): n for k, n in r["sources"].items()}
    train = [r for r in runs if not r["evaluating"]]
    p1 = [r for r in train if r["phase"] == 1]
    p1_goal = [r["steps"] for r in p1 if r["goal"]]
    best_example = min(p1_goal) if p1_goal else None
    mean_example = sum(p1_goal) / len(p1_goal) if p1_goal else None
    seqs = [e.seq for e in exps]
    gaps = sum(1 for a, b in zip(seqs, seqs[1:]) if b != a + 1)

    def ref(path):
        if not path:
            return None
        b = eval_blocks(path)
        return b[-1] if b else None

    optimal = ref(args.optimal)
    example = ref(args.example)
    examples = {}
    for item in args.example_gain:
        gain, _, path = item.partition("=")
        if not path:
            sys.exit("b21r_learning_report: --example-gain wants GAIN=LOG, got %r" % item)
        b = ref(path)
        if b is not None:
            examples[gain] = b
    if example is not None:
        examples.setdefault("nominal", example)
    bound = None
    try:
        import b21r_learn
        bound = list(b21r_learn.corridor_steps_lower_bound(args.corridor_length))
    except ImportError:
        pass
    verdicts = claims(blocks, optimal, examples, train)
    # Who drove each training run (the controller's experience sources).
    drivers = [{"run_id": r["run_id"], "phase": r["phase"], "steps": r["steps"], "goal": r["goal"],
                "sources": r["sources"]}
               for r in train]
    switch_after = next((b["training_runs"] for b in blocks if b["phase"] == 2), None)
    p2_blocks = [b for b in blocks if b["phase"] == 2]
    summary = {
        "blocks": blocks,
        "training_runs": len(train),
        "phase_one_runs": len(p1),
        "phase_two_runs": len(train) - len(p1),
        "phase_two_first_block_after_runs": switch_after,
        "best_example_steps": best_example,
        "mean_example_steps": mean_example,
        "optimal": optimal,
        "example_nominal": example,
        "experiences": len(exps),
        "experience_seq_gaps": gaps,
        "final_block": blocks[-1],
        "phase_two_all_starts_reached": bool(p2_blocks) and all(b["successes"] == b["n_starts"] for b in p2_blocks),
        "examples_by_gain": examples,
        "kinematic_bound_steps": bound,
        "claims": [{"claim": c, "holds": bool(ok), "numbers": n} for c, ok, n in verdicts],
        "training_runs_by_driver": drivers,
    }
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)

    # The learning curve (the paper's Fig. 4 layout).
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    for phase, colour, label in ((1, "tab:blue", "phase one (examples drive)"), (2, "tab:red", "phase two (learned policy drives)")):
        pts = [b for b in blocks if b["phase"] == phase and b["successes"] > 0]
        if pts:
            ax.errorbar([b["training_runs"] for b in pts], [b["mean_steps"] for b in pts],
                        yerr=[b["ci95_halfwidth"] for b in pts], fmt="o-", color=colour, capsize=3, label=label)
    xmax = max(b["training_runs"] for b in blocks) + 2
    if best_example is not None:
        ax.axhline(best_example, color="tab:green", ls="--", label="best example (%d steps)" % best_example)
    if optimal is not None and optimal["successes"] > 0:
        ax.axhline(optimal["mean_steps"], color="black", ls=":", label="optimal (%.1f steps)" % optimal["mean_steps"])
    if switch_after is not None:
        ax.axvline(switch_after - 2.5, color="grey", lw=0.8)
    ax.set_ylabel("steps to goal (mean, 95 % CI)")
    ax.set_title(args.title)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax2.bar([b["training_runs"] for b in blocks], [b["successes"] for b in blocks], width=2.5,
            color=["tab:blue" if b["phase"] == 1 else "tab:red" for b in blocks])
    ax2.set_ylim(0, max(b["n_starts"] for b in blocks) + 0.5)
    ax2.set_ylabel("reached goal")
    ax2.set_xlabel("training runs")
    ax2.set_xlim(0, xmax)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "learning_curve.png"), dpi=120)

    lines = ["Two-phase learning: %s" % args.title,
             "training runs: %d (phase one %d, phase two %d); experiences %d, sequence gaps %d" %
             (len(train), len(p1), len(train) - len(p1), len(exps), gaps),
             "best phase-one run: %s steps; mean phase-one run: %s steps (the examples)" %
             (best_example, "%.1f" % mean_example if mean_example is not None else None)]
    if optimal is not None:
        lines.append("optimal controller: %d/%d reached, %.1f +- %.1f steps" %
                     (optimal["successes"], optimal["n_starts"], optimal["mean_steps"], optimal["ci95_halfwidth"]))
    if bound is not None and optimal is not None:
        mb = sum(bound) / len(bound)
        lines.append("  kinematic lower bound from the same poses: %.1f steps; the optimal controller is %.1f steps "
                     "(%.1f %%) above it" % (mb, mean_all(optimal) - mb, 100.0 * (mean_all(optimal) / mb - 1.0)))
    for gain, b in sorted(examples.items()):
        lines.append("example policy (gain %s): %d/%d reached, %.1f steps (failures at the limit)" %
                     (gain, b["successes"], b["n_starts"], mean_all(b)))
    lines.append("evaluation blocks (learning off, %d fixed start poses; the learned policy only, no exploration):" % blocks[0]["n_starts"])
    for b in blocks:
        lines.append("  block %2d after %3d training runs, phase %d: %2d/%d reached, %.1f steps counting failures "
                     "at the limit, %s over reached" %
                     (b["block"], b["training_runs"], b["phase"], b["successes"], b["n_starts"], mean_all(b),
                      "%.1f +- %.1f" % (b["mean_steps"], b["ci95_halfwidth"]) if b["successes"] else "-"))
    by_phase = {}
    for r in train:
        agg = by_phase.setdefault(r["phase"], {})
        for src, n in r["sources"].items():
            agg[src] = agg.get(src, 0) + n
    for phase, agg in sorted(by_phase.items()):
        tot = sum(agg.values())
        lines.append("phase %d training steps by driver: %s" % (phase, ", ".join(
            "%s %d (%.1f %%)" % (src, n, 100.0 * n / tot) for src, n in sorted(agg.items()))))
    lines.append("claims (paired over the same poses, 95 %; this seed only, see docs/RESULTS.md for 10 seeds):")
    for c, ok, n in verdicts:
        lines.append("  %-3s %s: %s" % ("yes" if ok else "NO", c, n))
    with open(os.path.join(args.out, "summary.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
