#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.mcap: tools/b21r_mcap.py converts a real session's logs to MCAP, and the mcap library
reads back what the LCM logs hold. A short lockstep corridor session with the laser published
(inside netns-run) writes the controller's --log and --experience-log while lcm-logger records
over udpm; each log is converted and read back (the Foxglove schemas decoded from the protobuf
definitions the file carries, the product messages as JSON):
- every topic's message count equals its LCM channel's (the laser = B21R_SCAN, poses = B21R_POSE
  of a run, /command = B21R_EXPERIENCE, each product topic = its channel), and each message's
  log time is its LCM event's time;
- sampled values equal the LCM messages' (experience states, rewards, run records, status,
  laser ranges with NaN for no return, odometry);
- the task-frame pose of each run starts at its B21R_RUN start pose and stays in the corridor;
  the scene holds the corridor's four walls and the goal;
- the live bridge's estimate of a run's start from its first state (no B21R_RUN beforehand)
  matches the recorded start poses, in the corridor and among obstacles (a short obstacle session);
- a short doorway session (a task the tools know only from its declaration): its log converts,
  every run's task-frame pose starts at its record and stays in the room, the scene holds the
  room's four walls, the dividing wall's two and the goal disc, and the start estimates from the
  first state match the records.
usage: test_mcap.py CONTROLLER SIM REPO MCAP_TOOL"""
import math
import os
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

import b21r_foxglove as bf
import fwtest
from b21r import experience_t, pose_t, run_t, scan_t, status_t
from b21r_log import read_log

URL = "udpm://239.255.76.67:7667?ttl=0"


def read_mcap(path):
    """{topic: [(log_time_ns, decoded)]}: protobuf messages decoded, JSON ones as dicts."""
    import json
    out = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        json_channels = {cid for cid, ch in summary.channels.items() if ch.message_encoding == "json"}
        for schema, ch, msg in reader.iter_messages():
            if ch.id in json_channels:
                dec = json.loads(msg.data)
            else:
                dec = None  # decoded below, only for the topics checked value by value
            out.setdefault(ch.topic, []).append((msg.log_time, dec, schema, msg))
    return out


def decode_pb(entries):
    factory = DecoderFactory()
    decoders = {}
    res = []
    for t, _, schema, msg in entries:
        d = decoders.get(schema.id)
        if d is None:
            d = decoders[schema.id] = factory.decoder_for("protobuf", schema)
        res.append((t, d(msg.data)))
    return res


CORRIDOR_ROOM = {"box": (-0.3, 10.3, -1.0, 1.0), "walls": 4, "goal": "cubes", "name": "the corridor"}
DOORWAY_ROOM = {"box": (-4.5, 3.0, -3.0, 3.0), "walls": 6, "goal": "cylinders", "name": "the doorway's room"}
TASK_NAMES = {bf.TASK_CORRIDOR: "corridor", bf.TASK_OBSTACLES: "obstacles", bf.TASK_DOORWAY: "doorway"}


def check_log(log_path, tool, world_check=True, room=CORRIDOR_ROOM):
    out = log_path[:-len(".lcmlog")] + ".mcap"
    p = subprocess.run([sys.executable, tool, log_path, "--out", out], stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True, timeout=300)
    if p.returncode != 0:
        fwtest.fail("b21r_mcap.py %s: exit %d\n%s" % (log_path, p.returncode, p.stdout))
    events = read_log(log_path)
    mc = read_mcap(out)
    by_channel = {}
    for t_us, ch, m in events:
        by_channel.setdefault(ch, []).append((t_us * 1000, m))
    # Counts and times, topic by topic.
    expected = {topic: by_channel.get(ch, []) for ch, topic in bf.PRODUCT_TOPICS.items()}
    expected["/laser"] = by_channel.get("B21R_SCAN", [])
    expected["/odom/pose"] = [(t, m) for t, m in by_channel.get("B21R_POSE", []) if m.run_id >= 0]
    expected["/command"] = by_channel.get("B21R_EXPERIENCE", [])
    for topic, want in expected.items():
        got = mc.get(topic, [])
        if len(got) != len(want):
            fwtest.fail("%s: %s has %d messages, the LCM log %d" % (out, topic, len(got), len(want)))
        if [t for t, *_ in got] != [t for t, _ in want]:
            fwtest.fail("%s: %s log times differ from the LCM receive times" % (out, topic))
    # Values: the product messages field for field (every one), samples of the others.
    for ch, topic in bf.PRODUCT_TOPICS.items():
        for (t, m), (_, d, _, _) in zip(by_channel.get(ch, []), mc.get(topic, [])):
            if d != bf.lcm_to_dict(m):
                fwtest.fail("%s: %s message at %d differs from its LCM message" % (out, topic, t))
    exps = [m for _, m in by_channel.get("B21R_EXPERIENCE", [])]
    for e, (_, d, _, _) in zip(exps, mc.get("/b21r/experience", [])):
        if d["s"] != list(e.s[:e.state_dim]) or d["reward"] != e.reward or d["run_id"] != e.run_id:
            fwtest.fail("experience %d: state, reward or run differ" % e.seq)
    for e, (_, d, _, _) in zip(exps, mc.get("/command", [])):
        if d["angular"]["z"] != e.action_radps or d["linear"]["x"] != e.translation_mps:
            fwtest.fail("/command differs from the experience's command (seq %d)" % e.seq)
    scans = by_channel.get("B21R_SCAN", [])
    for (t, s), (_, ls) in list(zip(scans, decode_pb(mc.get("/laser", []))))[::97]:
        want = [float(r) if r > 0 else float("nan") for r in s.ranges_m[:s.n_beams]]
        got = list(ls.ranges)
        same = len(got) == len(want) and all((math.isnan(a) and math.isnan(b)) or abs(a - b) < 1e-6
                                             for a, b in zip(got, want))
        if not same or abs(ls.start_angle - s.angle_min_rad) > 1e-6 or ls.frame_id != "laser":
            fwtest.fail("/laser at %d differs from B21R_SCAN" % t)
    poses = expected["/odom/pose"]
    for (t, p), (_, pp) in list(zip(poses, decode_pb(mc.get("/odom/pose", []))))[::53]:
        if abs(pp.pose.position.x - p.x_m) > 1e-9 or abs(pp.pose.position.y - p.y_m) > 1e-9:
            fwtest.fail("/odom/pose at %d differs from B21R_POSE" % t)
    n_checked = 0
    if world_check and poses:
        records = {m.run_id: m for _, m in by_channel.get("B21R_RUN", [])}
        world = decode_pb(mc.get("/world/pose", []))
        if len(world) != len(poses):
            fwtest.fail("/world/pose: %d messages for %d poses of runs" % (len(world), len(poses)))
        first = {}
        x0, x1, y0, y1 = room["box"]
        for (t, p), (_, w) in zip(poses, world):
            x, y = w.pose.position.x, w.pose.position.y
            if not (x0 < x < x1 and y0 < y < y1):
                fwtest.fail("task-frame pose (%.2f, %.2f) of run %d lies outside %s" % (x, y, p.run_id, room["name"]))
            first.setdefault(p.run_id, (x, y))
        for run_id, (x, y) in first.items():
            r = records.get(run_id)
            if r is not None and (abs(x - r.start_x_m) > 1e-9 or abs(y - r.start_y_m) > 1e-9):
                fwtest.fail("run %d starts at (%.3f, %.3f) in the task frame, its record says (%.3f, %.3f)" %
                            (run_id, x, y, r.start_x_m, r.start_y_m))
            n_checked += r is not None
        scene = decode_pb(mc.get("/scene", []))
        if not scene:
            fwtest.fail("no /scene")
        ents = {e.id: e for e in scene[0][1].entities}
        if len(ents["walls"].cubes) != room["walls"] or not getattr(ents["goal"], room["goal"]):
            fwtest.fail("the scene does not hold %s's %d walls and its goal: %s" % (room["name"], room["walls"],
                                                                                  list(ents)))
    fwtest.note("%s: %d LCM messages, %d MCAP messages on %d topics; counts, times and values match%s" % (
        os.path.basename(out), len(events), sum(len(v) for v in mc.values()), len(mc),
        "; %d runs start at their recorded pose" % n_checked if n_checked else ""))
    return events


def check_start_estimates(events, task, tol_m, tol_rad):
    """The bridge's start of each run from its first state against the run's record."""
    world = bf.world_for(task, {}, repo=_repo)
    # Each run's first experience (it starts from the run's first state at any decision_ticks).
    firsts = {}
    for _, ch, m in events:
        if isinstance(m, experience_t):
            firsts.setdefault(m.run_id, m)
    worst = (0.0, 0.0)
    n = 0
    for _, ch, r in events:
        if not isinstance(r, run_t) or r.run_id not in firsts:
            continue
        e = firsts[r.run_id]
        est = bf.start_from_state(task, list(e.s[:e.state_dim]), world)
        if est is None:
            continue
        d = math.hypot(est[0] - r.start_x_m, est[1] - r.start_y_m)
        a = abs(math.atan2(math.sin(est[2] - r.start_theta_rad), math.cos(est[2] - r.start_theta_rad)))
        worst = (max(worst[0], d), max(worst[1], a))
        n += 1
    if n == 0 or worst[0] > tol_m or worst[1] > tol_rad:
        fwtest.fail("%s: start estimates of %d runs off by up to %.3f m, %.3f rad (tolerance %g m, %g rad)" %
                    (TASK_NAMES[task], n, worst[0], worst[1], tol_m, tol_rad))
    fwtest.note("%s: the start from the first state of %d runs within %.3f m, %.3f rad of the record" %
                (TASK_NAMES[task], n, worst[0], worst[1]))


_repo = None


def main():
    global _repo
    controller, sim_exe, repo, tool = sys.argv[1:5]
    from pathlib import Path
    _repo = Path(repo)
    d = fwtest.workdir("mcap")
    ok = False
    logger = None
    sim = None
    try:
        sim = fwtest.Sim(sim_exe, os.path.join(repo, "sim", "worlds", "corridor10.world"), d, "corridor")
        rec = os.path.join(d, "recording.lcmlog")
        logger = subprocess.Popen(["lcm-logger", "--lcm-url=%s&recv_buf_size=4194304" % URL, "--force", rec],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
        time.sleep(0.5)
        settings = {"lcm_url": URL, "publish_scan": "true", "phase_one_runs": 2, "phase_two_runs": 1,
                    "eval_every_runs": 3, "lockstep_realtime_factor": 30}
        cmd = fwtest.controller_cmd(controller, sim, d, "session", settings)
        cmd += ["--experience-log", os.path.join(d, "experiences.lcmlog")]
        with open(os.path.join(d, "session.controller.log"), "w") as err:
            rc = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=err, timeout=240).returncode
        if rc != 0:
            fwtest.fail("the controller exited with %d (see %s)" % (rc, err.name))
        time.sleep(0.5)
        logger.send_signal(signal.SIGINT)
        logger.wait(10)
        sim.close()
        sim = None
        events = check_log(os.path.join(d, "session.lcmlog"), tool)
        check_log(os.path.join(d, "experiences.lcmlog"), tool, world_check=False)
        check_log(rec, tool)
        check_start_estimates(events, bf.TASK_CORRIDOR, 0.15, 0.1)

        sim = fwtest.Sim(sim_exe, os.path.join(repo, "sim", "worlds", "obstacle1.world"), d, "obstacles")
        rc, err, log = fwtest.run_controller(controller, sim, d, "obstacles",
                                             {"task": "obstacles", "phase_one_runs": 6, "phase_two_runs": 0,
                                              "eval_every_runs": 100}, 240)
        if rc != 0:
            fwtest.fail("obstacle session: exit %d\n%s" % (rc, err[-2000:]))
        check_start_estimates(read_log(log), bf.TASK_OBSTACLES, 0.15, 0.1)
        sim.close()
        sim = None

        sim = fwtest.Sim(sim_exe, os.path.join(repo, "sim", "worlds", "doorway.world"), d, "doorway")
        rc, err, log = fwtest.run_controller(controller, sim, d, "doorway",
                                             {"task": "doorway", "phase_one_runs": 4, "phase_two_runs": 1,
                                              "eval_every_runs": 100}, 240)
        if rc != 0:
            fwtest.fail("doorway session: exit %d\n%s" % (rc, err[-2000:]))
        events = check_log(log, tool, room=DOORWAY_ROOM)
        runs = [m for _, _, m in events if isinstance(m, run_t)]
        train = [r for r in runs if r.kind == run_t.KIND_TRAINING]
        if len(train) != 5 or any(r.task != bf.TASK_DOORWAY for r in runs):
            fwtest.fail("doorway session: %d training run records of %d, tasks %s" % (
                len(train), len(runs), sorted({r.task for r in runs})))
        fwtest.note("doorway session: training runs ended %s" % [r.detail for r in train])
        check_start_estimates(events, bf.TASK_DOORWAY, 0.15, 0.1)
        ok = True
    finally:
        if logger is not None and logger.poll() is None:
            logger.kill()
            logger.wait()
        if sim is not None:
            sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
