#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_policy_map: pictures of what a controller checkpoint has learned, over a 2-D slice of the
state space, beside the teacher's and the optimal controller's actions.

    b21r_policy_map.py --checkpoint FILE [--out DIR] [--set KEY=VALUE]... [--grid N]
                       [--end-distance M] [--title TEXT]

Writes DIR/policy_map_<task>.png (default DIR: the checkpoint's folder) and the numbers behind it
in DIR/policy_map_<task>.json. Five panels over the same slice:
1. the learned value: Q at HEDGER's greedy action (the value the controller learns toward);
2. the learned policy's rotation command, as the controller drives it in an evaluation: HEDGER's
   greedy action, clamped to the action bounds, as the controller drives it;
3. the teacher's command: the example policy of phase one at its nominal gain (the controller's
   runs draw the gain per run from the task's range);
4. the optimal (hand-tuned reference) controller's command;
5. where the learner improved on the teacher: |learned - optimal| - |teacher - optimal| [rad/s]
   (blue: the learned policy is closer to the optimal controller than the teacher, red: farther).
Hatched grey: HEDGER's "unknown" region, where no stored experience supports any action (the
greedy search finds no known action): the controller there holds course in an evaluation and lets
the example policy advise in training; white: poses the robot cannot take (in a wall or obstacle).
Slices: corridor: lateral position (fraction of the width, 0 = left wall) x target angle, at
--end-distance from the end (default 5 m); any other task (obstacles, doorway, ...): the robot's
position over the region of its evaluation poses and its goal (0.8 m around them), facing the
goal, with the task's world (walls, obstacles, goal) drawn over it. The learner's state also holds the last command sent (state_rotation): the slice uses
the learned policy's own command (a_k+1 = pi(s, a_k), four steps from the teacher's; drawn is
pi(s, a_3)), i.e. the robot as it drives itself; the value panel at that command too.
The learner's settings are the controller's defaults for the checkpoint's task; give --set for
any learner key the controller ran with (the file is refused otherwise, with the reason).
Runs from a plain shell after tools/setup.sh and a build.
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import json
import math
import os
import sys

import gymnasium
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import b21r_learn  # noqa: E402
from b21r_task_world import wall_outline  # noqa: E402

FIXED_POINT_STEPS = 4
SLICE_MARGIN_M = 0.8


def nominal_gain(task):
    """The example policy's nominal gain: the middle of the task's declared gain range (the teacher
    is drawn there, as the main job's reference is)."""
    lo, hi = next(t["gain_range"] for t in b21r_learn._core.tasks() if t["name"] == task)
    return (lo + hi) / 2


def parse_set(items):
    out = {}
    for s in items:
        k, sep, v = s.partition("=")
        if not sep:
            sys.exit("b21r_policy_map: --set takes KEY=VALUE, not %r" % s)
        out[k.strip()] = v.strip()
    return out


def load(path, settings):
    """(HEDGER loaded from the checkpoint, its progress dict, the learner's config)."""
    try:
        meta, payload = b21r_learn.read_checkpoint(path)
        progress = b21r_learn.read_checkpoint_progress(meta)
    except ValueError as exc:
        sys.exit("b21r_policy_map: %s" % exc)
    task = progress["task"]
    try:
        cfg = b21r_learn.controller_learner_config(task, settings)
        h = b21r_learn.Hedger(**cfg)
        h.load(payload)
    except ValueError as exc:
        sys.exit("b21r_policy_map: %s: the learner does not take this state (%s); give --set for the learner "
                 "settings the controller ran with" % (path, exc))
    return h, progress, cfg


def slice_poses(task, env, grid, end_distance):
    """The slice: (axes (xs, ys, labels), [[pose or None]], features of each cell or None)."""
    if task == "corridor":
        spec = env.task_spec
        length, width = spec["length_m"], spec["width_m"]
        lookahead = spec.get("lookahead_m", 2.0)
        fs = np.linspace(0.0, 1.0, grid)
        angles = np.linspace(-1.0, 1.0, grid)
        poses = []
        for a in angles:
            row = []
            for f in fs:
                offset = (0.5 - f) * width  # y of the robot, + left (features/corridor.h)
                phi = a + math.atan2(offset, lookahead)
                row.append((length - end_distance, offset, -phi))
            poses.append(row)
        return (fs, angles, "lateral position (fraction of the width, 0 = left wall)", "target angle [rad]"), poses
    w = env.core.world()
    if w["goal"] is None:
        sys.exit("b21r_policy_map: task %s has no goal disc to face; its slice is not defined (the corridor's "
                 "slice is its own)" % task)
    gx, gy, _ = w["goal"]
    starts = env.task_spec["eval_starts"]
    px = [p[0] for p in starts] + [gx]
    py = [p[1] for p in starts] + [gy]
    xs = np.linspace(min(px) - SLICE_MARGIN_M, max(px) + SLICE_MARGIN_M, grid)
    ys = np.linspace(min(py) - SLICE_MARGIN_M, max(py) + SLICE_MARGIN_M, grid)
    poses = [[(x, y, math.atan2(gy - y, gx - x)) for x in xs] for y in ys]
    return (xs, ys, "x [m] (task frame; goal at (%g, %g))" % (gx, gy), "y [m]"), poses


def compute(h, progress, cfg, grid, end_distance):
    task = progress["task"]
    env = gymnasium.make(b21r_learn.envs.ENV_IDS[task], backend="kinematic").unwrapped
    omega_max = env.core.action_bound
    teacher = b21r_learn.Driver("proportional", task, gain=nominal_gain(task))
    optimal = b21r_learn.Driver("optimal", task)
    (ax_x, ax_y, label_x, label_y), poses = slice_poses(task, env, grid, end_distance)
    shape = (len(ax_y), len(ax_x))
    value, learned, teach, opt, command = (np.full(shape, np.nan) for _ in range(5))
    unknown = np.zeros(shape, dtype=bool)
    reachable = np.zeros(shape, dtype=bool)
    dim = h.state_dim
    for i, row in enumerate(poses):
        for j, pose in enumerate(row):
            try:
                obs, _ = env.reset(seed=1, options={"pose": pose})
            except ValueError:
                continue  # in a wall or an obstacle
            reachable[i, j] = True
            teacher.begin_run(0)
            optimal.begin_run(0)
            teach[i, j] = env.driver_action(teacher)
            opt[i, j] = env.driver_action(optimal)
            feats = np.asarray(obs, dtype=np.float64)
            # The last command in the learner's state: the policy's own, a_k+1 = pi(s, a_k) from the
            # teacher's; drawn is pi(s, a_K) with a_K the command of the last step.
            a_prev = teach[i, j]
            known = False
            for k in range(FIXED_POINT_STEPS):
                s = np.concatenate([feats, [a_prev]])[:dim] if dim > len(feats) else feats[:dim]
                a, v, _kind, known = h.greedy(np.ascontiguousarray(s))
                if not known:
                    break
                action = float(np.clip(a, -omega_max, omega_max))
                if k == FIXED_POINT_STEPS - 1:
                    value[i, j], learned[i, j], command[i, j] = v, action, a_prev
                a_prev = action
            if not known:
                unknown[i, j] = True
    return {"task": task, "x": ax_x, "y": ax_y, "label_x": label_x, "label_y": label_y, "value": value,
            "learned": learned, "command": command, "teacher": teach, "optimal": opt, "unknown": unknown, "reachable": reachable,
            "omega_max": omega_max, "world": env.core.world(), "end_distance": end_distance}


def summary(r, progress, path):
    known = r["reachable"] & ~r["unknown"]
    n_reach = int(r["reachable"].sum())
    d_learned = np.abs(r["learned"] - r["optimal"])[known]
    d_teacher = np.abs(r["teacher"] - r["optimal"])[known]
    return {
        "checkpoint": os.path.abspath(path), "task": r["task"], "cells": int(r["reachable"].size),
        "reachable_cells": n_reach, "unknown_cells": int((r["unknown"] & r["reachable"]).sum()),
        "unknown_fraction": float((r["unknown"] & r["reachable"]).sum() / max(1, n_reach)),
        "mean_abs_learned_minus_optimal_radps": float(d_learned.mean()) if d_learned.size else None,
        "mean_abs_teacher_minus_optimal_radps": float(d_teacher.mean()) if d_teacher.size else None,
        "learned_closer_fraction": float((d_learned < d_teacher).mean()) if d_learned.size else None,
        "teacher_gain": nominal_gain(r["task"]), "phase": progress["phase"],
        "training_runs": progress["training_runs"], "slice": {"x": r["label_x"], "y": r["label_y"],
                                                             "end_distance_m": r["end_distance"]},
    }


def draw(r, s, out_png, title):
    x, y = r["x"], r["y"]
    extent = [x[0] - (x[1] - x[0]) / 2, x[-1] + (x[1] - x[0]) / 2, y[0] - (y[1] - y[0]) / 2, y[-1] + (y[1] - y[0]) / 2]
    fig, axes = plt.subplots(1, 5, figsize=(24, 5.2), constrained_layout=True)
    w = r["omega_max"]
    panels = [
        ("learned value Q(s, greedy)", r["value"], "viridis", None, None, "value"),
        ("learned policy (greedy)", r["learned"], "coolwarm", -w, w,
         "rotation [rad/s]"),
        ("teacher: example policy, gain %.2f" % s["teacher_gain"], r["teacher"], "coolwarm", -w, w, "rotation [rad/s]"),
        ("optimal controller", r["optimal"], "coolwarm", -w, w, "rotation [rad/s]"),
        ("learned vs teacher: |learned-opt| - |teacher-opt|", np.abs(r["learned"] - r["optimal"]) -
         np.abs(r["teacher"] - r["optimal"]), "RdBu_r", -w, w, "[rad/s] (blue: learned closer)"),
    ]
    for k, (ax, (name, data, cmap, lo, hi, cbar)) in enumerate(zip(axes, panels)):
        im = ax.imshow(data, origin="lower", extent=extent, aspect="auto", cmap=cmap, vmin=lo, vmax=hi,
                       interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.05, pad=0.02).set_label(cbar)
        if k in (0, 1, 4):  # the panels that depend on what was learned
            unk = np.where(r["unknown"] & r["reachable"], 1.0, np.nan)
            ax.contourf(x, y, unk, levels=[0.5, 1.5], colors=["#c8c8c8"], hatches=["///"], zorder=2)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel(r["label_x"], fontsize=8)
        if k == 0:
            ax.set_ylabel(r["label_y"], fontsize=8)
        if r["task"] != "corridor":  # a slice in the task frame: the world over it
            wd = r["world"]
            for wall in wd["walls"]:
                solid = wall_outline(wall)
                if solid is not None:
                    ax.add_patch(plt.Polygon(solid, closed=True, color="#555555", zorder=3))
            for cx, cy, rad in wd["cylinders"]:
                ax.add_patch(plt.Circle((cx, cy), rad, color="#8a6d3b", zorder=3))
            gx, gy, gr = wd["goal"]
            ax.add_patch(plt.Circle((gx, gy), gr, facecolor="none", edgecolor="#2e7d32", lw=2, ls="--", zorder=3))
            ax.set_xlim(extent[0], extent[1])
            ax.set_ylim(extent[2], extent[3])
    unk = "%.0f %% of the slice unknown to HEDGER (hatched)" % (100 * s["unknown_fraction"])
    if s["mean_abs_learned_minus_optimal_radps"] is not None:
        unk += "; where known, |learned - optimal| %.3f rad/s vs |teacher - optimal| %.3f (learned closer in %.0f %%)" % (
            s["mean_abs_learned_minus_optimal_radps"], s["mean_abs_teacher_minus_optimal_radps"],
            100 * s["learned_closer_fraction"])
    where = ("end distance %.1f m" % r["end_distance"]) if r["task"] == "corridor" else "robot facing the goal"
    fig.suptitle("%s\n%s task, %s, after %d training runs (phase %d). %s" % (
        title, r["task"], where, s["training_runs"], s["phase"], unk), fontsize=10)
    fig.savefig(out_png, dpi=80)
    plt.close(fig)


def make_pictures(checkpoint, out_dir, settings=None, grid=41, end_distance=5.0, title=None):
    """Draws the checkpoint's map into out_dir; returns (png path, summary dict)."""
    h, progress, cfg = load(checkpoint, settings or {})
    r = compute(h, progress, cfg, grid, end_distance)
    s = summary(r, progress, checkpoint)
    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, "policy_map_%s.png" % r["task"])
    draw(r, s, png, title or "What was learned: %s" % os.path.basename(checkpoint))
    with open(os.path.join(out_dir, "policy_map_%s.json" % r["task"]), "w") as f:
        json.dump(s, f, indent=1)
    return png, s


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", required=True, help="the controller's checkpoint file (hedger.ckpt)")
    ap.add_argument("--out", help="folder for the PNG and JSON (default: the checkpoint's)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a controller setting the learner ran with (repeatable)")
    ap.add_argument("--grid", type=int, default=41, help="cells per axis (default %(default)s)")
    ap.add_argument("--end-distance", type=float, default=5.0, help="corridor: distance to the end [m] (default 5)")
    ap.add_argument("--title", help="the figure's first line")
    args = ap.parse_args()
    if args.grid < 3:
        ap.error("--grid must be at least 3")
    out = args.out or os.path.dirname(os.path.abspath(args.checkpoint))
    png, s = make_pictures(args.checkpoint, out, parse_set(args.set), args.grid, args.end_distance, args.title)
    print("%s: %s task, %d%% of the slice unknown%s" % (
        png, s["task"], round(100 * s["unknown_fraction"]),
        "" if s["learned_closer_fraction"] is None else
        "; the learned policy is closer to the optimal controller than the teacher in %d%% of the known cells" %
        round(100 * s["learned_closer_fraction"])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
