#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.log: b21r_log reads what the controller and lcm-logger write, finds every kind of loss
in an experience stream (a hole inside a run, a lost run end, whole runs lost), does not take a
controller restart for a gap, counts decisions held over several ticks (decision_ticks) as
complete runs with their steps, and its --runs output warns before any per-run number when the
log has gaps, with the runs it touches marked."""
import os
import subprocess
import sys
import tempfile
import unittest

import lcm
from b21r import command_t, command_v1_t, experience_t, pose_t, teleop_v1_t

import b21r_log

TOOL = os.path.join(os.path.dirname(os.path.abspath(b21r_log.__file__)), "b21r_log.py")


def exp(seq, run_id, step_id, terminal=False, reward=0.0, evaluating=False):
    e = experience_t()
    e.seq, e.run_id, e.step_id, e.terminal, e.reward, e.evaluating = seq, run_id, step_id, terminal, reward, evaluating
    e.phase, e.state_dim = 1, 3
    return e


def session(lengths, first_seq=0, first_run=0, ticks=1):
    """Experiences of consecutive runs with the given step counts, each ending at the goal; with
    ticks > 1 one per decision of that many ticks (at its last tick, and at the run's last)."""
    out = []
    seq = first_seq
    for i, n in enumerate(lengths):
        for k in range(n):
            if (k + 1) % ticks == 0 or k == n - 1:
                out.append(exp(seq, first_run + i, k, terminal=k == n - 1, reward=10.0 if k == n - 1 else 0.0))
                seq += 1
    return out


def write_log(path, messages):
    log = lcm.EventLog(path, "w", overwrite=True)
    for i, m in enumerate(messages):
        channel = "B21R_EXPERIENCE" if isinstance(m, experience_t) else "B21R_POSE"
        log.write_event(1000 * i, channel, m.encode())
    log.close()


class Runs(unittest.TestCase):
    def test_complete_stream_counts_steps_and_goals(self):
        runs = b21r_log.runs_from_experiences(session([5, 3, 4]))
        self.assertEqual([r["steps"] for r in runs], [5, 3, 4])
        self.assertTrue(all(r["complete"] and r["goal"] for r in runs))
        self.assertEqual(b21r_log.experience_gaps(session([5, 3, 4])), [])

    def test_hole_inside_a_run_marks_it(self):
        s = session([5, 3, 4])
        del s[2]  # run 0, step 2
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual(runs[0]["steps"], 5)
        self.assertEqual(runs[0]["received"], 4)
        self.assertFalse(runs[0]["complete"])
        self.assertTrue(runs[1]["complete"] and runs[2]["complete"])
        self.assertEqual(b21r_log.experience_gaps(s), [(2, 3)])

    def test_lost_run_end_marks_the_run_whose_end_is_missing(self):
        s = session([5, 3, 4])
        del s[3:5]  # run 0's last two steps, its terminal among them
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual(runs[0]["steps"], 3)  # all that can be known
        self.assertFalse(runs[0]["complete"])
        self.assertFalse(runs[0]["goal"])
        self.assertTrue(runs[1]["complete"])
        self.assertEqual(b21r_log.missing_count(b21r_log.experience_gaps(s)), 2)

    def test_whole_run_lost_is_named(self):
        s = session([5, 3, 4])
        del s[5:8]  # all of run 1
        self.assertEqual(b21r_log.missing_runs(s), [1])
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual([r["run_id"] for r in runs], [0, 2])
        self.assertTrue(runs[0]["complete"])  # it ended at the goal: nothing of it was lost

    def test_decisions_held_over_ticks(self):
        # decision_ticks = 3: one experience per decision; runs ending inside a decision included.
        s = session([7, 9, 2], ticks=3)
        self.assertEqual(b21r_log.decision_spacing(s), 3)
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual([r["steps"] for r in runs], [7, 9, 2])
        self.assertEqual([r["received"] for r in runs], [3, 3, 1])
        self.assertTrue(all(r["complete"] and r["goal"] for r in runs))
        self.assertEqual([r["sources"] for r in runs], [{0: 7}, {0: 9}, {0: 2}])  # steps, not experiences
        del s[4]  # run 1's second decision
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual((runs[1]["steps"], runs[1]["received"], runs[1]["sources"]), (9, 2, {0: 6}))
        self.assertFalse(runs[1]["complete"])
        self.assertTrue(runs[0]["complete"] and runs[2]["complete"])
        self.assertEqual(b21r_log.decision_spacing(session([5, 3])), 1)

    def test_restart_is_not_a_gap(self):
        s = session([5, 3]) + session([4, 2], first_seq=0, first_run=2)
        self.assertEqual(b21r_log.experience_gaps(s), [])
        runs = b21r_log.runs_from_experiences(s)
        self.assertEqual([r["steps"] for r in runs], [5, 3, 4, 2])
        self.assertTrue(all(r["complete"] for r in runs))


class CommandLine(unittest.TestCase):
    def run_tool(self, messages, *args):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "t.lcmlog")
            write_log(path, messages)
            p = subprocess.run([sys.executable, TOOL, path, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, timeout=60)
            return p.returncode, p.stdout.splitlines()

    def test_runs_warns_first_when_the_log_has_gaps(self):
        s = session([5, 3, 4])
        del s[3:5]
        pose = pose_t()
        rc, lines = self.run_tool([pose] + s + [pose], "--runs")
        self.assertEqual(rc, 1)
        self.assertTrue(lines[0].startswith("warning: this log is missing 2 experiences in 1 gaps"), lines)
        self.assertIn("1 run(s) marked *", lines[0])
        self.assertEqual(lines[1], "run    0 phase 1 train    3 steps -  * incomplete (3 experiences received)")
        self.assertEqual(lines[2], "run    1 phase 1 train    3 steps goal")

    def test_complete_log_has_no_warning(self):
        rc, lines = self.run_tool(session([5, 3]), "--runs", "--gaps")
        self.assertEqual(rc, 0)
        self.assertEqual(lines, ["8 experiences, 0 gaps, 0 missing", "run    0 phase 1 train    5 steps goal",
                                 "run    1 phase 1 train    3 steps goal"])

    def test_messages_decode_by_type_on_any_channel(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "t.lcmlog")
            log = lcm.EventLog(path, "w", overwrite=True)
            log.write_event(5, "SOME_OTHER_NAME", exp(7, 1, 2).encode())
            log.write_event(6, "NOT_LCM_TYPED", b"12345678 garbage")
            log.close()
            events = b21r_log.read_log(path)
        self.assertEqual(len(events), 1)
        self.assertEqual(events[0][1], "SOME_OTHER_NAME")
        self.assertEqual(events[0][2].seq, 7)

    def test_old_operator_messages_read_and_unknown_types_named(self):
        # A recording from before the operator messages were signed: its TELEOP and COMMAND decode
        # as the v1 types; an event of a type this build does not know is skipped and named.
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "old.lcmlog")
            old_t = teleop_v1_t()
            old_t.seq, old_t.deadman, old_t.rotation_radps = 3, True, 0.25
            old_c = command_v1_t()
            old_c.seq, old_c.command = 4, command_t.PAUSE
            log = lcm.EventLog(path, "w", overwrite=True)
            log.write_event(1, "B21R_TELEOP", old_t.encode())
            log.write_event(2, "B21R_COMMAND", old_c.encode())
            log.write_event(3, "B21R_STATUS", b"\x01\x02\x03\x04\x05\x06\x07\x08 an older status_t")
            log.close()
            events = b21r_log.read_log(path)
            p = subprocess.run([sys.executable, TOOL, path], capture_output=True, text=True, timeout=60)
        self.assertEqual([type(m) for _, _, m in events], [teleop_v1_t, command_v1_t])
        self.assertEqual((events[0][2].rotation_radps, events[1][2].command), (0.25, command_t.PAUSE))
        self.assertEqual(p.returncode, 0)
        self.assertIn("skipped 1 events of message types this build does not know (B21R_STATUS 1)", p.stderr)
        self.assertEqual(len(p.stdout.splitlines()), 2)


if __name__ == "__main__":
    unittest.main()
