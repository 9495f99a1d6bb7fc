#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_log: read B21R_* LCM event logs (lcm-logger files, or the controller's --log and
--experience-log files) into Python objects, and check an experience stream for gaps.

Library use:
    from b21r_log import read_log, experience_gaps, runs_from_experiences
    events = read_log("run.lcmlog")            # [(timestamp_us, channel, decoded message), ...]
Command line:
    b21r_log.py FILE [--channel B21R_EVAL] [--gaps] [--runs]
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
generated types).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import sys

import lcm

try:
    from b21r import command_t, eval_t, experience_t, pose_t, scan_t, status_t, teleop_t
except ImportError as exc:  # pragma: no cover - a usage error, explained
    sys.exit("b21r_log: the generated LCM types are not importable (%s); build them: %s" % (exc, b21r_bootstrap.BUILD_HINT))

TYPES = {
    "B21R_EXPERIENCE": experience_t,
    "B21R_STATUS": status_t,
    "B21R_POSE": pose_t,
    "B21R_EVAL": eval_t,
    "B21R_SCAN": scan_t,
    "B21R_TELEOP": teleop_t,
    "B21R_COMMAND": command_t,
}


def read_log(path, channels=None):
    """All events of the log (optionally only the given channels), decoded, in file order."""
    out = []
    log = lcm.EventLog(path, "r")
    try:
        for ev in log:
            if channels is not None and ev.channel not in channels:
                continue
            t = TYPES.get(ev.channel)
            if t is None:
                continue
            out.append((ev.timestamp, ev.channel, t.decode(ev.data)))
    finally:
        log.close()
    return out


def experience_gaps(experiences):
    """Sequence gaps in a stream of experience_t (the controller numbers them 0, 1, 2, ...).
    Returns a list of (expected_seq, got_seq)."""
    gaps = []
    expect = None
    for e in experiences:
        if expect is not None and e.seq != expect:
            gaps.append((expect, e.seq))
        expect = e.seq + 1
    return gaps


def runs_from_experiences(experiences):
    """One dict per run: run_id, phase, evaluating, steps, reached goal, sources used."""
    runs = {}
    order = []
    for e in experiences:
        r = runs.get(e.run_id)
        if r is None:
            r = {"run_id": e.run_id, "phase": e.phase, "evaluating": bool(e.evaluating), "steps": 0,
                 "goal": False, "terminal": False, "return": 0.0, "sources": {}}
            runs[e.run_id] = r
            order.append(e.run_id)
        r["steps"] = max(r["steps"], e.step_id + 1)
        r["return"] += e.reward
        r["sources"][e.source] = r["sources"].get(e.source, 0) + 1
        if e.terminal:
            r["terminal"] = True
            r["goal"] = e.reward > 0.0
    return [runs[i] for i in order]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log")
    ap.add_argument("--channel", action="append", help="only this channel (repeatable)")
    ap.add_argument("--gaps", action="store_true", help="check B21R_EXPERIENCE for sequence gaps")
    ap.add_argument("--runs", action="store_true", help="one line per run from B21R_EXPERIENCE")
    args = ap.parse_args()
    if args.gaps or args.runs:
        exps = [m for _, _, m in read_log(args.log, {"B21R_EXPERIENCE"})]
        if args.gaps:
            gaps = experience_gaps(exps)
            print("%d experiences, %d gaps%s" % (len(exps), len(gaps), (": %s" % gaps[:10]) if gaps else ""))
        if args.runs:
            for r in runs_from_experiences(exps):
                print("run %4d phase %d %-5s %4d steps %s" % (r["run_id"], r["phase"],
                      "eval" if r["evaluating"] else "train", r["steps"], "goal" if r["goal"] else "-"))
        return 1 if args.gaps and experience_gaps(exps) else 0
    for t, ch, m in read_log(args.log, set(args.channel) if args.channel else None):
        fields = {k: getattr(m, k) for k in m.__slots__}
        print(t, ch, fields)
    return 0


if __name__ == "__main__":
    sys.exit(main())
