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
  summary.json        every number of the plot, machine-readable
  summary.txt         the same for people
Usage:
  b21r_learning_report.py --log LEARN.lcmlog [--optimal OPT.lcmlog] [--example EX.lcmlog] --out OUTDIR
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
    ap.add_argument("--out", required=True)
    ap.add_argument("--title", default="Corridor following, emulated B21r")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    blocks = eval_blocks(args.log)
    if not blocks:
        sys.exit("b21r_learning_report: no B21R_EVAL in %s" % args.log)
    exps = [m for _, _, m in read_log(args.log, {"B21R_EXPERIENCE"})]
    runs = runs_from_experiences(exps)
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
             "best example run: %s steps; mean example run: %s steps" %
             (best_example, "%.1f" % mean_example if mean_example is not None else None)]
    if optimal is not None:
        lines.append("optimal controller: %d/%d reached, %.1f +- %.1f steps" %
                     (optimal["successes"], optimal["n_starts"], optimal["mean_steps"], optimal["ci95_halfwidth"]))
    if example is not None:
        lines.append("example policy (nominal gain): %d/%d reached, %.1f +- %.1f steps" %
                     (example["successes"], example["n_starts"], example["mean_steps"], example["ci95_halfwidth"]))
    lines.append("evaluation blocks (learning off, %d fixed start poses):" % blocks[0]["n_starts"])
    for b in blocks:
        lines.append("  block %2d after %3d training runs, phase %d: %2d/%d reached, mean %s steps" %
                     (b["block"], b["training_runs"], b["phase"], b["successes"], b["n_starts"],
                      "%.1f +- %.1f" % (b["mean_steps"], b["ci95_halfwidth"]) if b["successes"] else "-"))
    lines.append("phase two reached the goal from every start in every block: %s" %
                 ("yes" if summary["phase_two_all_starts_reached"] else "no"))
    with open(os.path.join(args.out, "summary.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
