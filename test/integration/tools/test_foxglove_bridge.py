#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.foxglove_bridge: the live view. Inside netns-run (LCM over udpm on a private loopback)
tools/b21r_session.py --foxglove starts the bridge beside a short lockstep session (laser
published, an evaluation block after 2 runs); a WebSocket client speaking foxglove.websocket.v1
(the `websockets` package; foxglove-sdk's server names it foxglove.sdk.v1) connects and subscribes to every channel. Checked:
- the advertised channels are the conversion's topics with their schemas (protobuf Foxglove
  schemas, JSON Schemas), and every topic of the Foxglove layout in the repository is among them;
- decoded messages arrive on each: laser scans of 181 beams in frame laser, the robot's
  task-frame pose inside the corridor, transforms, the scene's four walls, commands, the
  learning curve after the evaluation block;
- every experience received equals, field for field, the experience of the same seq in the
  controller's own --log.
usage: test_foxglove_bridge.py REPO"""
import asyncio
import base64
import json
import os
import re
import signal
import struct
import subprocess
import sys
import time
from types import SimpleNamespace

import websockets
from mcap_protobuf.decoder import DecoderFactory

import b21r_foxglove as bf
import fwtest
from b21r_log import read_log

PORT = 18765
# foxglove-sdk's server speaks the Foxglove WebSocket protocol under the name foxglove.sdk.v1 (its
# successor of foxglove.websocket.v1, the same messages); a client offers both, as Foxglove does.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def layout_topics(repo):
    with open(os.path.join(repo, "tools", "foxglove", "b21r-layout.json")) as f:
        text = f.read()
    json.loads(text)  # valid JSON
    return set(re.findall(r'"(/(?:[a-z0-9_]+/)*[a-z0-9_]+)[".\[]', text))


async def watch(url, seconds, want):
    """Subscribes to every advertised channel; returns (channels by id, {topic: [decoded]})."""
    got = {}
    channels = {}
    decoders = {}
    factory = DecoderFactory()
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS, max_size=None) as ws:
        if ws.subprotocol not in SUBPROTOCOLS:
            fwtest.fail("the bridge answered with subprotocol %r" % ws.subprotocol)
        fwtest.note("connected: subprotocol %s" % ws.subprotocol)
        deadline = time.monotonic() + seconds
        sub_id = 0
        subs = {}
        while time.monotonic() < deadline:
            try:
                frame = await asyncio.wait_for(ws.recv(), timeout=1.0)
            except asyncio.TimeoutError:
                frame = None
            if isinstance(frame, str):
                m = json.loads(frame)
                if m.get("op") == "advertise":
                    new = []
                    for ch in m["channels"]:
                        channels[ch["id"]] = ch
                        sub_id += 1
                        subs[sub_id] = ch["id"]
                        new.append({"id": sub_id, "channelId": ch["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif isinstance(frame, bytes) and frame[0] == 0x01:
                sid, _log_time = struct.unpack_from("<IQ", frame, 1)
                ch = channels[subs[sid]]
                payload = frame[13:]
                if ch["encoding"] == "json":
                    dec = json.loads(payload)
                else:
                    d = decoders.get(ch["id"])
                    if d is None:
                        schema = SimpleNamespace(id=ch["id"], name=ch["schemaName"], encoding="protobuf",
                                                 data=base64.b64decode(ch["schema"]))
                        d = decoders[ch["id"]] = factory.decoder_for("protobuf", schema)
                    dec = d(payload)
                got.setdefault(ch["topic"], []).append(dec)
            if all(len(got.get(t, [])) >= n for t, n in want.items()):
                break
    return channels, got


def main():
    repo = sys.argv[1]
    d = fwtest.workdir("foxglove")
    ok = False
    launcher = None
    try:
        out = os.path.join(d, "session")
        log_path = os.path.join(d, "launcher.txt")
        with open(log_path, "w") as log:
            launcher = subprocess.Popen(
                [sys.executable, os.path.join(repo, "tools", "b21r_session.py"), "--out", out, "--lockstep",
                 "--pace", "10", "--no-spy", "--foxglove", "--foxglove-port", str(PORT),
                 "--set", "publish_scan=true", "--set", "phase_one_runs=1000", "--set", "eval_every_runs=2"],
                stdout=log, stderr=subprocess.STDOUT, env=dict(os.environ, DISPLAY=""))
        deadline = time.time() + 60
        while True:
            with open(log_path) as f:
                text = f.read()
            if "started foxglove" in text and os.path.exists(os.path.join(out, "foxglove.log")):
                with open(os.path.join(out, "foxglove.log")) as f:
                    if "serving" in f.read():
                        break
            if launcher.poll() is not None or time.time() > deadline:
                fwtest.fail("the launcher did not start the bridge:\n%s" % text)
            time.sleep(0.2)
        want = {"/laser": 5, "/world/pose": 5, "/tf": 5, "/scene": 1, "/command": 5, "/b21r/experience": 20,
                "/b21r/status": 5, "/b21r/eval": 1, "/b21r/learning_curve": 1, "/world/trajectory": 1,
                "/b21r/run": 1}
        channels, got = asyncio.run(watch("ws://127.0.0.1:%d" % PORT, 150, want))
        launcher.send_signal(signal.SIGINT)
        rc = launcher.wait(90)
        with open(log_path) as f:
            text = f.read()
        if rc != 130 or not re.search(r"stopped foxglove\s+pid", text):
            fwtest.fail("launcher exit %d, or the bridge not stopped with it:\n%s" % (rc, text))

        topics = {c["topic"]: c for c in channels.values()}
        expected = bf.all_topics()
        missing = (set(expected) | {"/b21r/learning_curve"}) - set(topics)
        if missing:
            fwtest.fail("the bridge does not advertise %s" % sorted(missing))
        for t, (kind, spec) in expected.items():
            c = topics[t]
            name = spec.get_schema().name if kind == "protobuf" else spec["title"]
            if c["encoding"] != kind or c["schemaName"] != name:
                fwtest.fail("%s advertised as %s/%s, expected %s/%s" % (t, c["encoding"], c["schemaName"], kind, name))
        not_served = layout_topics(repo) - set(topics)
        if not_served:
            fwtest.fail("the layout tools/foxglove/b21r-layout.json shows topics the bridge does not serve: %s" %
                        sorted(not_served))
        short = {t: len(got.get(t, [])) for t, n in want.items() if len(got.get(t, [])) < n}
        if short:
            fwtest.fail("too few messages received: %s (want %s)" % (short, want))
        scan = got["/laser"][-1]
        if len(scan.ranges) != 181 or scan.frame_id != "laser":
            fwtest.fail("a scan of %d beams in frame %r" % (len(scan.ranges), scan.frame_id))
        for p in got["/world/pose"]:
            if not (-0.3 < p.pose.position.x < 10.3 and -1.0 < p.pose.position.y < 1.0) or p.frame_id != "world":
                fwtest.fail("task-frame pose outside the corridor: %s" % p)
        walls = [e for e in got["/scene"][-1].entities if e.id == "walls"]
        if not walls or len(walls[0].cubes) != 4:
            fwtest.fail("the scene does not hold the corridor's four walls")
        frames = {(t.parent_frame_id, t.child_frame_id) for m in got["/tf"] for t in m.transforms}
        for pair in (("world", "odom"), ("odom", "base_link"), ("base_link", "laser")):
            if pair not in frames:
                fwtest.fail("no transform %s -> %s among %s" % (pair[0], pair[1], sorted(frames)))
        curve = got["/b21r/learning_curve"][-1]["blocks"]
        if not curve or curve[0]["n_starts"] != 10 or curve[0]["training_runs"] != 2:
            fwtest.fail("learning curve %s" % curve)
        by_seq = {m.seq: bf.lcm_to_dict(m) for _, _, m in read_log(os.path.join(out, "controller.lcmlog"),
                                                                     {"B21R_EXPERIENCE"})}
        for e in got["/b21r/experience"]:
            if by_seq.get(e["seq"]) != e:
                fwtest.fail("experience seq %d over the WebSocket differs from the controller's log" % e["seq"])
        fwtest.note("bridge: %d channels advertised (the layout's %d topics among them); received %s; %d experiences "
                    "equal the controller's log; learning curve %d block(s)" % (
                        len(channels), len(layout_topics(repo)),
                        ", ".join("%s %d" % (t, len(got[t])) for t in sorted(want)), len(got["/b21r/experience"]),
                        len(curve)))
        ok = True
    finally:
        if launcher is not None and launcher.poll() is None:
            launcher.send_signal(signal.SIGINT)
            try:
                launcher.wait(60)
            except subprocess.TimeoutExpired:
                launcher.kill()
                launcher.wait()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
