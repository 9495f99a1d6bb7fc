#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_trajectories: draws the robot's trajectories from any LCM log with B21R_POSE messages
(the controller's --log, an lcm-logger recording; emulator or robot).

    b21r_trajectories.py LOG --out FILE.png [--panels phase|eval|all] [--world FILE]
                         [--frame auto|task|odometry] [--title TEXT]

One panel per phase (training runs; --panels phase, the default), one per evaluation block
(--panels eval), or one for every run (--panels all). In each panel the runs are coloured in
order (the same colour scale as b21r-sim's --trace-svg picture) with a legend (a colour bar when
there are many), a triangle at each start pose, a circle at each end pose, a red cross where a
run ended in a collision, and the goal.
Frames: B21R_POSE is the base's odometry, continuous over the whole session. In the task frame
(= the emulator's world frame) each run is placed at its start pose: the one its B21R_RUN record
gives (any task; the controller's --log has them), else the one recovered from the run's first
B21R_EXPERIENCE state for the corridor task (end distance, lateral position and target angle give
x, y and heading). The task's world is drawn: the corridor and its goal line, or any other task's
walls, obstacles and goal as its declaration builds them (lib/tasks, through b21r_learn; the
configuration's task_params are not in an experience log: give --world FILE for another room);
--world FILE draws that world instead. Runs whose start is unknown (another task's log without run
records, logs without experiences) are drawn in the odometry frame, where the goal is unknown.
Phases, evaluation blocks and run ends come from B21R_EXPERIENCE and B21R_EVAL; without them all
runs are drawn in one panel.
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
generated types).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from b21r import experience_t  # noqa: E402
from b21r_log import FIRST_DECISION_STEPS, read_log  # noqa: E402
from b21r_task_world import WorldUnavailable, declared_world, task_name, wall_outline  # noqa: E402

# B21R_RUN end_reason -> the names below ("stopped": a safety stop or pause, "shutdown").
RUN_END_NAMES = {0: "goal", 1: "collision", 2: "limit", 3: "stopped", 4: "shutdown"}

# The corridor task's defaults (lib/tasks tasks_corridor_spec_default, features/corridor.h).
CORRIDOR = {"length_m": 10.0, "width_m": 2.0, "goal_distance_m": 1.0, "lookahead_m": 2.0}
COLOUR_SPAN = 0.9  # use viridis[0, 0.9]: its last tenth is too pale on white
LEGEND_MAX_RUNS = 12


def run_colour(i, n):
    return plt.cm.viridis(COLOUR_SPAN * (i / max(1, n - 1)))


class Run:
    def __init__(self, run_id):
        self.run_id = run_id
        self.poses = []       # (step_id, x, y, theta) in the odometry frame
        self.phase = None
        self.evaluating = None
        self.first_state = None
        self.start_record = None  # the task-frame start of its B21R_RUN record, where the log has one
        self.task = None
        self.end = None       # "goal", "collision", "limit", "stopped", "shutdown" or None (unknown)
        self.block = None

    def path(self, frame):
        if frame == "odometry" or self.start_task is None:
            return [(x, y, th) for _, x, y, th in self.poses]
        _, x0, y0, th0 = self.poses[0]
        sx, sy, sth = self.start_task
        out = []
        c0, s0 = math.cos(th0), math.sin(th0)
        cs, ss = math.cos(sth), math.sin(sth)
        for _, x, y, th in self.poses:  # the start pose composed with the odometry since the start
            dx, dy = x - x0, y - y0
            lx, ly = c0 * dx + s0 * dy, -s0 * dx + c0 * dy
            out.append((sx + cs * lx - ss * ly, sy + ss * lx + cs * ly, sth + th - th0))
        return out

    @property
    def start_task(self):
        if self.start_record is not None:
            return self.start_record
        if self.first_state is None or self.task != experience_t.TASK_CORRIDOR:
            return None
        return corridor_pose(self.first_state)


def corridor_pose(s):
    """Task-frame pose from the corridor state (features/corridor.h): end distance d, lateral
    fraction f (0 left wall, 1 right wall), target angle a = phi - atan2(offset, L), phi = -heading."""
    d, f, a = s[0], s[1], s[2]
    offset = (0.5 - f) * CORRIDOR["width_m"]
    phi = a + math.atan2(offset, CORRIDOR["lookahead_m"])
    return (CORRIDOR["length_m"] - d, offset, -phi)


def load(path):
    runs = {}
    order = []
    evals = []
    records = {}
    for _, ch, m in read_log(path, {"B21R_POSE", "B21R_EXPERIENCE", "B21R_EVAL", "B21R_RUN"}):
        if ch == "B21R_EVAL":
            evals.append(m)
            continue
        if m.run_id < 0:
            continue  # poses before the first run
        r = runs.get(m.run_id)
        if r is None:
            r = runs[m.run_id] = Run(m.run_id)
            order.append(m.run_id)
        if ch == "B21R_POSE":
            r.poses.append((m.step_id, m.x_m, m.y_m, m.theta_rad))
        elif ch == "B21R_RUN":
            records[m.run_id] = m
        else:
            if r.phase is None:  # the run's first experience
                r.phase, r.evaluating, r.task = m.phase, bool(m.evaluating), m.task
                # It starts from the run's first state: with decisions over N ticks it ends at
                # step N - 1, its s the state at step 0 (a later one means the first was lost).
                if m.step_id < FIRST_DECISION_STEPS:
                    r.first_state = tuple(m.s[:m.state_dim])
            if m.terminal:
                r.end = "goal" if m.reward > 0 else "collision"
            elif r.end is None:
                r.end = "limit"
    # The controller's end records (B21R_RUN), where the log has them, are the authority: they also
    # describe runs that ended without a terminal state or whose experiences are missing.
    for run_id, m in records.items():
        r = runs[run_id]
        r.phase, r.evaluating, r.task = m.phase, m.kind == 1, m.task
        r.end = RUN_END_NAMES.get(m.end_reason, "limit")
        r.start_record = (m.start_x_m, m.start_y_m, m.start_theta_rad)
    out = [runs[i] for i in order if runs[i].poses]
    for r in out:
        r.poses.sort()
    # Evaluation blocks: consecutive evaluation runs, numbered as the B21R_EVAL messages.
    block, prev_eval = -1, False
    for r in out:
        if r.evaluating:
            if not prev_eval:
                block += 1
            r.block = block
        prev_eval = bool(r.evaluating)
    return out, evals


def panels_of(runs, evals, how):
    if how == "all" or all(r.phase is None for r in runs):
        return [("all runs", runs)]
    if how == "eval":
        blocks = sorted({r.block for r in runs if r.block is not None})
        out = []
        for b in blocks:
            members = [r for r in runs if r.block == b]
            e = evals[b] if b < len(evals) else None
            title = "evaluation block %d" % b
            if e is not None:
                title += " after %d training runs (phase %d): %d/%d reached the goal" % (
                    e.training_runs, e.phase, e.successes, e.n_starts)
            out.append((title, members))
        return out
    out = []
    for phase in sorted({r.phase for r in runs if r.phase is not None}):
        members = [r for r in runs if r.phase == phase and not r.evaluating]
        if members:
            goals = sum(1 for r in members if r.end == "goal")
            out.append(("phase %d: %d training runs, %d reached the goal" % (phase, len(members), goals), members))
    return out


def read_world(path):
    """The parts of a b21r-sim world file (sim/include/sim/world.h) that are drawn."""
    w = {"walls": [], "cylinders": [], "goal": None, "corridor": None, "starts": []}
    with open(path) as f:
        for line in f:
            t = line.split("#", 1)[0].split()
            if not t:
                continue
            v = [float(x) for x in t[1:] if _is_number(x)]
            if t[0] == "corridor" and len(v) >= 2:
                w["corridor"] = (v[0], v[1])
            elif t[0] == "arena" and len(v) == 4:
                x0, y0, x1, y1 = v
                w["walls"] += [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]
            elif t[0] == "wall" and len(v) >= 4:
                w["walls"].append(tuple(v[:5]) if len(v) >= 5 else tuple(v[:4]) + (0.10,))
            elif t[0] == "cylinder" and len(v) >= 3:
                w["cylinders"].append(tuple(v[:3]))
            elif t[0] == "goal" and len(v) >= 3:
                w["goal"] = tuple(v[:3])
            elif t[0] == "start" and len(v) >= 3:
                w["starts"].append(tuple(v[:3]))
    return w


def _is_number(x):
    try:
        float(x)
        return True
    except ValueError:
        return False


def default_world(task=experience_t.TASK_CORRIDOR):
    """The world of the log's task: the paper's corridor, or another task's as declared. Raises
    WorldUnavailable (with the reason) where it cannot be built."""
    if task == experience_t.TASK_CORRIDOR:
        return {"walls": [], "cylinders": [], "goal": None, "starts": [],
                "corridor": (CORRIDOR["length_m"], CORRIDOR["width_m"])}
    name = task_name(task)
    if name is None:
        raise WorldUnavailable("the log's task byte %d is not a declared task" % task)
    return declared_world(name)


def draw_world(ax, w):
    kw = dict(color="#555555", lw=3, solid_capstyle="butt", zorder=1)
    if w["corridor"] is not None:
        length, width = w["corridor"]
        ax.plot([0, length, length, 0, 0], [width / 2, width / 2, -width / 2, -width / 2, width / 2], **kw)
        gx = length - CORRIDOR["goal_distance_m"]
        ax.plot([gx, gx], [-width / 2, width / 2], color="#2e7d32", lw=2, ls="--", zorder=1)
    for wall in w["walls"]:
        solid = wall_outline(wall)
        if solid is not None:
            ax.add_patch(plt.Polygon(solid, closed=True, color="#555555", zorder=1))
        else:
            ax.plot([wall[0], wall[2]], [wall[1], wall[3]], **kw)
    for x, y, r in w["cylinders"]:
        ax.add_patch(plt.Circle((x, y), r, color="#8a6d3b", zorder=1))
    if w["goal"] is not None:
        x, y, r = w["goal"]
        ax.add_patch(plt.Circle((x, y), r, facecolor="#b8e6b8", edgecolor="#2e7d32", ls="--", lw=2, zorder=1))


def draw_panel(ax, title, runs, frame, world):
    if frame == "task" and world is not None:
        draw_world(ax, world)
    n = len(runs)
    for i, r in enumerate(runs):
        c = run_colour(i, n)
        p = r.path(frame)
        xs, ys = [q[0] for q in p], [q[1] for q in p]
        ax.plot(xs, ys, color=c, lw=1.2, zorder=2, label="run %d" % r.run_id)
        x0, y0, th0 = p[0]
        ax.plot([x0], [y0], marker=(3, 0, math.degrees(th0) - 90), ms=9, color=c, mec="black", mew=0.5, zorder=3)
        ax.plot([xs[-1]], [ys[-1]], marker="o", ms=5, mfc="none", mec=c, zorder=3)
        if r.end == "collision":
            ax.plot([xs[-1]], [ys[-1]], marker="x", ms=11, mew=2.5, color="#c62828", zorder=4)
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, color="#e4e4dc", lw=0.6)
    ax.set_xlabel("x [m] (%s frame)" % frame)
    ax.set_ylabel("y [m]")
    if n <= LEGEND_MAX_RUNS:
        handles = [Line2D([], [], color=run_colour(i, n), lw=2, label="run %d" % r.run_id) for i, r in enumerate(runs)]
    else:
        handles = []
        sm = plt.cm.ScalarMappable(cmap="viridis", norm=matplotlib.colors.Normalize(
            runs[0].run_id, runs[0].run_id + (runs[-1].run_id - runs[0].run_id) / COLOUR_SPAN))
        cb = ax.figure.colorbar(sm, ax=ax, fraction=0.04, pad=0.02)
        cb.set_label("run id")
        cb.ax.set_ylim(runs[0].run_id, runs[-1].run_id)
    handles += [Line2D([], [], ls="", marker=(3, 0, -90), ms=9, color="#999999", mec="black", mew=0.5,
                       label="start pose"),
                Line2D([], [], ls="", marker="o", mfc="none", mec="#555555", label="end"),
                Line2D([], [], ls="", marker="x", ms=9, mew=2.5, color="#c62828", label="collision")]
    if frame == "task" and world is not None:
        handles.append(Line2D([], [], color="#2e7d32", ls="--", lw=2, label="goal"))
    ax.legend(handles=handles, fontsize=7, loc="best", framealpha=0.85)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log")
    ap.add_argument("--out", required=True, help="picture file (.png, .svg, .pdf)")
    ap.add_argument("--panels", choices=("phase", "eval", "all"), default="phase")
    ap.add_argument("--frame", choices=("auto", "task", "odometry"), default="auto")
    ap.add_argument("--world", help="b21r-sim world file drawn in the task frame (default: the log's task's world: "
                                    "the paper's corridor, or the task's as declared)")
    ap.add_argument("--title", default=None)
    args = ap.parse_args()
    try:
        runs, evals = load(args.log)
    except IOError as exc:
        sys.exit("b21r_trajectories: cannot read %s: %s" % (args.log, exc))
    if not runs:
        sys.exit("b21r_trajectories: no B21R_POSE of a run in %s" % args.log)
    task_known = all(r.start_task is not None for r in runs)
    frame = args.frame if args.frame != "auto" else ("task" if task_known else "odometry")
    if frame == "task" and not task_known:
        sys.exit("b21r_trajectories: the task frame needs every run's start pose: its B21R_RUN record (any task; "
                 "the controller's --log has them) or, for the corridor task, its B21R_EXPERIENCE; use --frame odometry")
    world = None
    if frame == "task":
        task = next((r.task for r in runs if r.task is not None), experience_t.TASK_CORRIDOR)
        try:
            world = read_world(args.world) if args.world else default_world(task)
        except WorldUnavailable as exc:
            sys.exit("b21r_trajectories: %s; give --world FILE (sim/worlds/) or use --frame odometry" % exc)
    panels = panels_of(runs, evals, args.panels)
    if not panels:
        sys.exit("b21r_trajectories: no runs for --panels %s in %s" % (args.panels, args.log))
    cols = min(2, len(panels))
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(7.5 * cols, 4.2 * rows), squeeze=False)
    for ax, (title, members) in zip(axes.flat, panels):
        draw_panel(ax, title, members, frame, world)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.suptitle(args.title or "Trajectories: %s" % args.log, fontsize=11)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print("b21r_trajectories: %d runs in %d panel(s), %s frame -> %s" % (sum(len(m) for _, m in panels), len(panels),
                                                                        frame, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
