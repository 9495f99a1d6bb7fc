#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.trajectories: b21r_trajectories places every corridor run at its start pose in the task
frame (recovered from the run's first experience state) whatever the odometry frame, draws one
panel per phase or per evaluation block with a legend naming the runs, start poses, ends,
collisions and the goal, and falls back to the odometry frame where the task frame is unknown.
Any task's runs with B21R_RUN records (the doorway's here) are placed at their recorded starts
and drawn in the task's declared world; a task byte no task declares is refused with the reason."""
import math
import os
import subprocess
import sys
import tempfile
import unittest

import lcm
from b21r import eval_t, experience_t, pose_t, run_t

import b21r_trajectories as bt

TOOL = os.path.join(os.path.dirname(os.path.abspath(bt.__file__)), "b21r_trajectories.py")
L, W, LA = 10.0, 2.0, 2.0


def corridor_state(x, y, th):
    f = 0.5 - y / W
    return (L - x, f, -th - math.atan2(y, LA))


def session(path, task=experience_t.TASK_CORRIDOR):
    """Four runs: two phase-one training runs (the second a collision), one evaluation run, one
    phase-two training run; the odometry frame is rotated and shifted against the task frame."""
    log = lcm.EventLog(path, "w", overwrite=True)
    odo_rot, odo_dx, odo_dy = 0.7, 5.0, -3.0
    truth = {}
    seq = 0
    t = 0
    plan = [(0, 1, False, (1.0, 0.5, 0.2), "goal"), (1, 1, False, (1.5, -0.4, -0.3), "collision"),
            (2, 1, True, (1.0, 0.0, 0.0), "goal"), (3, 2, False, (0.8, 0.3, 0.1), "goal")]
    for run_id, phase, evaluating, (x0, y0, th0), end in plan:
        pts = [(x0 + 0.5 * k * math.cos(th0), y0 + 0.5 * k * math.sin(th0), th0) for k in range(6)]
        truth[run_id] = pts
        for k, (x, y, th) in enumerate(pts):
            p = pose_t()
            p.run_id, p.step_id = run_id, k + 1
            c, s = math.cos(odo_rot), math.sin(odo_rot)
            p.x_m, p.y_m, p.theta_rad = odo_dx + c * x - s * y, odo_dy + s * x + c * y, th + odo_rot
            log.write_event(t, "B21R_POSE", p.encode())
            t += 1
            if k + 1 < len(pts):
                e = experience_t()
                e.seq, e.run_id, e.step_id, e.phase, e.evaluating, e.task = seq, run_id, k, phase, evaluating, task
                e.state_dim = 3
                e.s = list(corridor_state(x, y, th)) + [0.0] * 5
                e.s_next = list(corridor_state(*pts[k + 1])) + [0.0] * 5
                last = k + 2 == len(pts)
                e.terminal = last
                e.reward = 10.0 if last and end == "goal" else 0.0
                log.write_event(t, "B21R_EXPERIENCE", e.encode())
                seq += 1
                t += 1
        if evaluating:
            ev = eval_t()
            ev.block, ev.training_runs, ev.phase, ev.n_starts, ev.successes = 0, 2, 1, 1, 1
            log.write_event(t, "B21R_EVAL", ev.encode())
    log.close()
    return truth


def session_with_runs(path, task):
    """Two runs of any task with their B21R_RUN records (start poses in the task frame) and no
    usable state (zeros); the odometry frame rotated and shifted against the task frame."""
    log = lcm.EventLog(path, "w", overwrite=True)
    odo_rot, odo_dx, odo_dy = -0.4, 2.0, 1.0
    truth = {}
    t = 0
    for run_id, (x0, y0, th0), end in ((0, (-2.5, 1.0, -0.3), 0), (1, (-3.0, -0.5, 0.2), 1)):
        pts = [(x0 + 0.4 * k * math.cos(th0), y0 + 0.4 * k * math.sin(th0), th0) for k in range(5)]
        truth[run_id] = pts
        for k, (x, y, th) in enumerate(pts):
            p = pose_t()
            p.run_id, p.step_id = run_id, k + 1
            c, s = math.cos(odo_rot), math.sin(odo_rot)
            p.x_m, p.y_m, p.theta_rad = odo_dx + c * x - s * y, odo_dy + s * x + c * y, th + odo_rot
            log.write_event(t, "B21R_POSE", p.encode())
            t += 1
            e = experience_t()
            e.run_id, e.step_id, e.phase, e.task, e.state_dim = run_id, k, 1, task, 4
            e.s = [0.0] * 8
            e.s_next = [0.0] * 8
            log.write_event(t, "B21R_EXPERIENCE", e.encode())
            t += 1
        r = run_t()
        r.run_id, r.kind, r.phase, r.task, r.end_reason = run_id, 0, 1, task, end
        r.start_x_m, r.start_y_m, r.start_theta_rad = x0, y0, th0
        r.detail = "goal" if end == 0 else "collision"
        log.write_event(t, "B21R_RUN", r.encode())
        t += 1
    log.close()
    return truth


class Frames(unittest.TestCase):
    def test_corridor_start_pose_recovered_and_paths_in_task_frame(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "s.lcmlog")
            truth = session(path)
            runs, evals = bt.load(path)
        self.assertEqual([r.run_id for r in runs], [0, 1, 2, 3])
        self.assertEqual([r.end for r in runs], ["goal", "collision", "goal", "goal"])
        self.assertEqual([r.block for r in runs], [None, None, 0, None])
        for r in runs:
            for (x, y, th), (tx, ty, tth) in zip(r.path("task"), truth[r.run_id]):
                self.assertAlmostEqual(x, tx, places=9)
                self.assertAlmostEqual(y, ty, places=9)
                self.assertAlmostEqual(th, tth, places=9)
        odo = runs[0].path("odometry")[0]
        self.assertAlmostEqual(odo[0], 5.0 + math.cos(0.7) * 1.0 - math.sin(0.7) * 0.5, places=9)

    def test_panels_per_phase_and_per_block(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "s.lcmlog")
            session(path)
            runs, evals = bt.load(path)
        phase = bt.panels_of(runs, evals, "phase")
        self.assertEqual([(t.split(":")[0], [r.run_id for r in m]) for t, m in phase],
                         [("phase 1", [0, 1]), ("phase 2", [3])])
        self.assertIn("1 reached the goal", phase[0][0])
        blocks = bt.panels_of(runs, evals, "eval")
        self.assertEqual([[r.run_id for r in m] for _, m in blocks], [[2]])
        self.assertIn("1/1 reached the goal", blocks[0][0])


class CommandLine(unittest.TestCase):
    def run_tool(self, *args, task=experience_t.TASK_CORRIDOR):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "s.lcmlog")
            session(path, task)
            out = os.path.join(d, "t.svg")
            p = subprocess.run([sys.executable, TOOL, path, "--out", out, *args], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, timeout=120)
            svg = ""
            if os.path.exists(out):
                with open(out) as f:
                    svg = f.read()
        return p, svg

    def test_picture_has_panels_legend_and_goal(self):
        p, svg = self.run_tool()
        self.assertEqual(p.returncode, 0, p.stdout)
        self.assertIn("3 runs in 2 panel(s), task frame", p.stdout)
        for text in ("phase 1: 2 training runs", "phase 2: 1 training runs", "run 0", "run 1", "run 3",
                     "start pose", "collision", "goal", "task frame"):
            self.assertIn(text, svg)

    def test_doorway_runs_at_their_recorded_starts_in_the_declared_room(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "s.lcmlog")
            truth = session_with_runs(path, experience_t.TASK_DOORWAY)
            runs, _ = bt.load(path)
            for r in runs:
                for (x, y, th), (tx, ty, tth) in zip(r.path("task"), truth[r.run_id]):
                    self.assertAlmostEqual(x, tx, places=9)
                    self.assertAlmostEqual(y, ty, places=9)
                    self.assertAlmostEqual(th, tth, places=9)
            w = bt.default_world(experience_t.TASK_DOORWAY)
            self.assertEqual(len(w["walls"]), 6)  # the room's four and the dividing wall's two
            self.assertIsNotNone(w["goal"])
            out = os.path.join(d, "t.svg")
            p = subprocess.run([sys.executable, TOOL, path, "--out", out], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, timeout=120)
            self.assertEqual(p.returncode, 0, p.stdout)
            self.assertIn("2 runs in 1 panel(s), task frame", p.stdout)
            # A task byte no task declares: a clear refusal in the task frame, no traceback.
            session_with_runs(path, 99)
            p = subprocess.run([sys.executable, TOOL, path, "--out", out, "--frame", "task"], stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True, timeout=120)
            self.assertNotEqual(p.returncode, 0)
            self.assertIn("not a declared task", p.stdout)
            self.assertNotIn("Traceback", p.stdout)

    def test_other_task_falls_back_to_odometry(self):
        p, svg = self.run_tool(task=experience_t.TASK_OBSTACLES)
        self.assertEqual(p.returncode, 0, p.stdout)
        self.assertIn("odometry frame", p.stdout)
        p, _ = self.run_tool("--frame", "task", task=experience_t.TASK_OBSTACLES)
        self.assertNotEqual(p.returncode, 0)
        self.assertIn("--frame odometry", p.stdout)


if __name__ == "__main__":
    unittest.main()
