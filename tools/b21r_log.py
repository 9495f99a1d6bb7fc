#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_log: read B21R_* LCM event logs (lcm-logger files, or the controller's --log and
--experience-log files) into Python objects, and check an experience stream for gaps.

Library use:
    from b21r_log import read_log, experience_gaps, runs_from_experiences, runs_from_records, read_config
    events = read_log("run.lcmlog")            # [(timestamp_us, channel, decoded message), ...]
Command line:
    b21r_log.py FILE [--channel B21R_EVAL] [--gaps] [--runs] [--config]
      --gaps   count the experiences and list the sequence gaps (exit status 1 when any)
      --runs   one line per run: from its B21R_RUN end record when the log has them (end reason,
               steps by driver, return), else from B21R_EXPERIENCE; when experiences are missing
               a warning comes first and the runs it touches are marked
      --config print the controller's effective configuration (B21R_CONFIG) and its limits
The controller's --log file stamps events with the wall clock (the controller's own time, which
is simulated in lockstep, is each message's utime); its --experience-log file with utime.
Messages are decoded by their LCM type fingerprint, so every type of the project is read
whatever the channel is called; B21R_TELEOP and B21R_COMMAND recorded before they were signed
decode as teleop_v1_t and command_v1_t. Events of a type this build does not know (another
version of a message) are skipped, and listing the events says how many, per channel. A controller restart inside one recording (seq starting again
at 0) begins a new segment and is not counted as a gap.
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
generated types).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import bisect
import os
import signal
import sys

import lcm

try:
    import b21r
except ImportError as exc:  # pragma: no cover - a usage error, explained
    sys.exit("b21r_log: the generated LCM types are not importable (%s); build them: %s" % (exc, b21r_bootstrap.BUILD_HINT))


def _types_by_fingerprint():
    types = {}
    for name in dir(b21r):
        t = getattr(b21r, name)
        if isinstance(t, type) and hasattr(t, "_get_packed_fingerprint"):
            types[t._get_packed_fingerprint()] = t
    return types


FINGERPRINTS = _types_by_fingerprint()


def read_log(path, channels=None, skipped=None, cut=False):
    """All events of the log with a B21R type (optionally only the given channels), decoded, in
    file order: [(timestamp_us, channel, message)]. Events of unknown types are skipped, and
    counted per channel in the dict `skipped` when one is given. cut=True reads a log that is
    still being written or that a SIGKILL cut anywhere: a missing or empty file gives [], and
    reading stops at a torn last event."""
    out = []
    if cut and (not os.path.exists(path) or os.path.getsize(path) == 0):
        return out
    log = lcm.EventLog(path, "r")
    try:
        while True:
            try:
                ev = log.read_next_event()
            except Exception:
                if not cut:
                    raise
                break  # a torn last event
            if ev is None:
                break
            if channels is not None and ev.channel not in channels:
                continue
            t = FINGERPRINTS.get(bytes(ev.data[:8]))
            if t is None:
                if skipped is not None:
                    skipped[ev.channel] = skipped.get(ev.channel, 0) + 1
                continue
            try:
                out.append((ev.timestamp, ev.channel, t.decode(ev.data)))
            except Exception:
                if not cut:
                    raise
                break
    finally:
        log.close()
    return out


def experience_gaps(experiences):
    """Sequence gaps in a stream of experience_t (the controller numbers them 0, 1, 2, ... per
    process). A seq of 0 after a higher one is a restart of the controller, not a gap.
    Returns a list of (expected_seq, got_seq)."""
    gaps = []
    expect = None
    for e in experiences:
        if expect is not None and e.seq != expect and not (e.seq == 0 and expect > 0):
            gaps.append((expect, e.seq))
        expect = e.seq + 1
    return gaps


# A run's first decision ends before this step (decision_ticks is at most 10, the controller's
# FW_DECISION_TICKS_MAX): its experience is the run's first and starts from the run's first state.
FIRST_DECISION_STEPS = 10


def restarted(prev, e):
    """True when experience e starts a new controller process after prev (its seq is 0 again):
    run ids and sequence numbers begin anew there."""
    return prev is not None and e.seq == 0 and prev.seq > 0


def missing_count(gaps):
    """Experiences lost in the given gaps (reordered or repeated ones count 0)."""
    return sum(max(0, got - want) for want, got in gaps)


def decision_spacing(experiences):
    """The ticks between a run's experiences (the controller's decision_ticks: one experience per
    decision, at its last tick): the most common step_id difference between consecutive
    experiences of a run, its last one left out (a run may end inside a decision); the smallest of
    equally common ones (a lost experience makes a larger one); 1 when no run has three
    experiences."""
    steps = {}
    segment = 0
    prev = None
    for e in experiences:
        if restarted(prev, e):
            segment += 1  # a controller restart: run ids may repeat
        steps.setdefault((segment, e.run_id), []).append(e.step_id)
        prev = e
    counts = {}
    for ids in steps.values():
        for a, b in zip(ids[:-2], ids[1:-1]):
            if b > a:
                counts[b - a] = counts.get(b - a, 0) + 1
    return max(sorted(counts), key=lambda d: counts[d]) if counts else 1


def runs_from_experiences(experiences):
    """One dict per run, in order of first appearance: run_id, phase, evaluating, steps (actions
    taken: the last step_id seen + 1), received (experiences present), goal, terminal, return (the
    experiences' rewards summed: with decisions over several ticks each is its ticks' rewards
    discounted within the decision, so the run's own return only at one tick per decision; the
    B21R_RUN records' is exact, runs_from_records),
    sources (steps per source: each experience counts the ticks since the run's previous one, at
    most the log's decision_spacing), and complete: False when experiences of the run are missing
    (a hole in its step_ids, or a sequence gap right after it while it had not ended, so that its
    last steps may be lost); the numbers of an incomplete run are lower bounds."""
    spacing = decision_spacing(experiences)
    runs = []
    by_id = {}
    prev = None
    for e in experiences:
        if restarted(prev, e):
            by_id = {}  # a controller restart: run ids may repeat
        r = by_id.get(e.run_id)
        if r is None:
            r = {"run_id": e.run_id, "phase": e.phase, "evaluating": bool(e.evaluating), "steps": 0, "received": 0,
                 "goal": False, "terminal": False, "return": 0.0, "sources": {}, "complete": True}
            by_id[e.run_id] = r
            if runs and prev is not None and e.seq != prev.seq + 1 and not runs[-1]["terminal"]:
                runs[-1]["complete"] = False  # the lost experiences may have been its end
            runs.append(r)
        ticks = min(max(e.step_id + 1 - r["steps"], 0), spacing)
        r["steps"] = max(r["steps"], e.step_id + 1)
        r["received"] += 1
        r["return"] += e.reward
        r["sources"][e.source] = r["sources"].get(e.source, 0) + ticks
        if e.terminal:
            r["terminal"] = True
            r["goal"] = e.reward > 0.0
        prev = e
    for r in runs:
        if r["received"] != -(-r["steps"] // spacing):  # one experience per decision, the last one maybe short
            r["complete"] = False
    return runs


END_NAMES = {0: "goal", 1: "collision", 2: "step limit", 3: "stopped", 4: "shutdown"}
SOURCE_NAMES = ("example", "joystick", "greedy", "exploration", "advisor")


def runs_from_records(records, experiences=()):
    """One dict per B21R_RUN end record, in order: run_id, phase, evaluating, steps, end (END_NAMES),
    detail, return, sources ({source name: steps}), start (x, y, theta), experiences (as the
    controller produced them), received (experiences of the run present in `experiences`) and
    complete: False when fewer were received than produced (only judged when experiences are
    given). A controller restart (seq of 0 again) starts a new segment of run ids."""
    present = {}
    segment = 0
    prev = None
    for e in experiences:
        if restarted(prev, e):
            segment += 1
        # Experiences of a run lie in [first_seq, first_seq + experiences): count by seq range.
        present.setdefault(segment, []).append(e.seq)
        prev = e
    seqs = {k: sorted(set(v)) for k, v in present.items()}
    runs = []
    segment = 0
    prev_id = None
    for r in records:
        if prev_id is not None and r.first_seq == 0 and r.run_id <= prev_id:
            segment += 1
        prev_id = r.run_id
        received = None
        if experiences:
            s = seqs.get(segment, [])
            received = bisect.bisect_left(s, r.first_seq + r.experiences) - bisect.bisect_left(s, r.first_seq)
        runs.append({"run_id": r.run_id, "phase": r.phase, "evaluating": r.kind == 1, "steps": r.steps,
                     "end": END_NAMES.get(r.end_reason, str(r.end_reason)), "detail": r.detail,
                     "return": r.total_reward,
                     "sources": {SOURCE_NAMES[i]: n for i, n in enumerate(r.steps_by_source) if n},
                     "start": (r.start_x_m, r.start_y_m, r.start_theta_rad), "experiences": r.experiences,
                     "received": received, "complete": received is None or received == r.experiences})
    return runs


def read_config(path):
    """The controller's B21R_CONFIG of the log (the first one) as (settings dict, message), or
    (None, None) when the log has none."""
    for _, _, m in read_log(path, {"B21R_CONFIG"}):
        settings = {}
        for line in m.text.splitlines():
            key, sep, value = line.partition(" = ")
            if sep:
                settings[key] = value.strip('"')
        return settings, m
    return None, None


def missing_runs(experiences):
    """Run ids of which no experience at all is present (run ids count every run, training and
    evaluation, from 0 per controller process or from the checkpoint's count)."""
    missing = []
    prev = None
    for e in experiences:
        if prev is not None and not restarted(prev, e) and e.run_id > prev.run_id + 1:
            missing.extend(range(prev.run_id + 1, e.run_id))
        prev = e
    return missing


def main():
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `b21r_log.py FILE | head` ends quietly
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log")
    ap.add_argument("--channel", action="append", help="only this channel (repeatable)")
    ap.add_argument("--gaps", action="store_true", help="check B21R_EXPERIENCE for sequence gaps")
    ap.add_argument("--runs", action="store_true",
                    help="one line per run (from B21R_RUN when present, else from B21R_EXPERIENCE)")
    ap.add_argument("--config", action="store_true", help="print the controller's configuration (B21R_CONFIG)")
    args = ap.parse_args()
    try:
        if args.config:
            settings, msg = read_config(args.log)
        elif args.gaps or args.runs:
            events = read_log(args.log, {"B21R_EXPERIENCE", "B21R_RUN"})
            exps = [m for _, ch, m in events if isinstance(m, b21r.experience_t)]
            records = [m for _, ch, m in events if isinstance(m, b21r.run_t)]
        else:
            skipped = {}
            events = read_log(args.log, set(args.channel) if args.channel else None, skipped)
    except IOError as exc:
        sys.exit("b21r_log: cannot read %s: %s" % (args.log, exc))
    if args.config:
        if msg is None:
            sys.exit("b21r_log: %s has no B21R_CONFIG (recorded by controllers that publish it at start)" % args.log)
        print("# limits: translation %g m/s (%g m/s^2), rotation %g rad/s (%g rad/s^2), teleop timeout %g s, "
              "%g Hz, step limit %d%s" % (msg.max_translation_mps, msg.max_translation_accel_mps2,
                                          msg.max_rotation_radps, msg.max_rotation_accel_radps2,
                                          msg.teleop_timeout_s, msg.tick_rate_hz, msg.step_limit,
                                          ", lockstep" if msg.lockstep else ""))
        sys.stdout.write(msg.text)
        return 0
    if not (args.gaps or args.runs):
        if skipped:
            print("b21r_log: skipped %d events of message types this build does not know (%s): recorded by "
                  "another version of the controller or the tools" %
                  (sum(skipped.values()), ", ".join("%s %d" % kv for kv in sorted(skipped.items()))), file=sys.stderr)
            sys.stderr.flush()
        for t, ch, m in events:
            fields = {k: getattr(m, k) for k in m.__slots__}
            print(t, ch, fields)
        return 0
    gaps = experience_gaps(exps)
    if args.gaps:
        print("%d experiences, %d gaps, %d missing%s" % (len(exps), len(gaps), missing_count(gaps),
                                                        (": %s" % gaps[:10]) if gaps else ""))
    if args.runs and records:
        runs = runs_from_records(records, exps)
        incomplete = [r for r in runs if not r["complete"]]
        if gaps or incomplete:
            print("warning: this log is missing %d experiences in %d gaps; %d run(s) marked * lack experiences "
                  "(their end records are complete)" % (missing_count(gaps), len(gaps), len(incomplete)),
                  file=sys.stderr)
            sys.stderr.flush()
        for r in runs:
            print("run %4d phase %d %-5s %4d steps %-10s return %8.2f  %s%s" % (
                r["run_id"], r["phase"], "eval" if r["evaluating"] else "train", r["steps"], r["end"], r["return"],
                " ".join("%s %d" % kv for kv in r["sources"].items()),
                "" if r["complete"] else "  * %d of %d experiences present" % (r["received"], r["experiences"])))
    elif args.runs:
        runs = runs_from_experiences(exps)
        incomplete = [r for r in runs if not r["complete"]]
        lost_runs = missing_runs(exps)
        if gaps or incomplete:
            print("warning: this log is missing %d experiences in %d gaps%s; the numbers of the %d run(s) marked * "
                  "are lower bounds (the controller's own --log loses nothing)" %
                  (missing_count(gaps), len(gaps),
                   ", among them every experience of run(s) %s" % lost_runs[:20] if lost_runs else "",
                   len(incomplete)), file=sys.stderr)
            sys.stderr.flush()
        for r in runs:
            end = "goal" if r["goal"] else ("end" if r["terminal"] else "-")
            print("run %4d phase %d %-5s %4d steps %s%s" % (r["run_id"], r["phase"],
                  "eval" if r["evaluating"] else "train", r["steps"], end,
                  "" if r["complete"] else "  * incomplete (%d experiences received)" % r["received"]))
    return 1 if gaps else 0


if __name__ == "__main__":
    sys.exit(main())
