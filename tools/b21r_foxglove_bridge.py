#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_foxglove_bridge: serves the controller's LCM channels live to Foxglove over a WebSocket
(foxglove-sdk's server, protocol foxglove.websocket.v1), so a person opens Foxglove, connects to
ws://HOST:PORT and watches the robot learn: the laser, the robot in its corridor or arena with
its trajectory, the command, the learning curve as the evaluation blocks come.

    b21r_foxglove_bridge.py [--lcm-url URL] [--host 127.0.0.1] [--port 8765] [--world FILE]

Topics: those of tools/b21r_foxglove.py (the same conversion as the MCAP converter), plus
/b21r/learning_curve, every evaluation block so far in one JSON message, so a viewer that
connects late still sees the whole curve. The scene (walls, obstacles, goal) and the learning
curve are sent again every --repeat-s seconds for viewers that connect later. Open
tools/foxglove/b21r-layout.json in Foxglove (Layouts, Import from file) for the one-click view.
The bridge only listens: it never publishes on LCM. --host 0.0.0.0 serves other machines (the
Foxglove WebSocket protocol has no authentication: only on a trusted network).
Ctrl-C or SIGTERM stops it. Runs from a plain shell after tools/setup.sh and a build.
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import json
import select
import signal
import sys
import time

import foxglove
import lcm

import b21r_foxglove as bf
from b21r_log import FINGERPRINTS

HOST_LOCAL_URL = "udpm://239.255.76.67:7667?ttl=0"
LEARNING_CURVE_SCHEMA = {
    "title": "b21r.learning_curve",
    "type": "object",
    "properties": {"blocks": {"type": "array", "items": {"type": "object", "properties": {
        "block": {"type": "integer"}, "training_runs": {"type": "integer"}, "phase": {"type": "integer"},
        "mean_steps": {"type": "number"}, "ci95_halfwidth": {"type": "number"},
        "successes": {"type": "integer"}, "n_starts": {"type": "integer"}}}}},
}


class Bridge:
    """LCM in, Foxglove channels out: one foxglove.Channel per topic, advertised from the start."""

    def __init__(self, world_file=None, context=None):
        self.conv = bf.Converter(b21r_bootstrap.REPO, world_file=world_file)
        self.kinds = bf.all_topics()
        self.kinds["/b21r/learning_curve"] = ("json", LEARNING_CURVE_SCHEMA)
        self.channels = {}
        for topic, (kind, spec) in self.kinds.items():
            if kind == "protobuf":
                s = spec.get_schema()
                schema = foxglove.Schema(name=s.name, encoding="protobuf", data=bytes(s.data))
                enc = "protobuf"
            else:
                schema = foxglove.Schema(name=spec["title"], encoding="jsonschema", data=json.dumps(spec).encode())
                enc = "json"
            kw = {"context": context} if context is not None else {}
            self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding=enc, **kw)
        self.blocks = []
        self.received = 0
        self.undecoded = 0

    def publish(self, topic, message, t_ns):
        self.channels[topic].log(bf.encode(self.kinds[topic][0], message), log_time=t_ns)

    def on_lcm(self, channel, data):
        t_ns = time.time_ns()
        t = FINGERPRINTS.get(bytes(data[:8]))
        if t is None:
            self.undecoded += 1
            return
        msg = t.decode(data)
        self.received += 1
        for topic, m in self.conv.convert(channel, msg, t_ns):
            self.publish(topic, m, t_ns)
        if channel == "B21R_EVAL":
            self.blocks.append({k: getattr(msg, k) for k in ("block", "training_runs", "phase", "mean_steps",
                                                             "ci95_halfwidth", "successes", "n_starts")})
            self.publish("/b21r/learning_curve", {"blocks": self.blocks}, t_ns)

    def repeat(self):
        """The state a viewer that connects now needs: the scene and the learning curve."""
        t_ns = time.time_ns()
        if self.conv.world is not None:
            self.publish("/scene", bf.scene_entities(self.conv.world, t_ns), t_ns)
        if self.blocks:
            self.publish("/b21r/learning_curve", {"blocks": self.blocks}, t_ns)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lcm-url", default=HOST_LOCAL_URL, help="LCM provider (default: %(default)s)")
    ap.add_argument("--host", default="127.0.0.1", help="address to serve on (default: %(default)s)")
    ap.add_argument("--port", type=int, default=8765, help="WebSocket port (default: %(default)s; 0: any free port)")
    ap.add_argument("--world", help="b21r-sim world file to draw (default: the task's)")
    ap.add_argument("--repeat-s", type=float, default=2.0, help="resend the scene and the learning curve every "
                                                                 "this many seconds (default: %(default)g)")
    args = ap.parse_args()
    stop = []
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, lambda n, f: stop.append(n))
    try:
        lc = lcm.LCM(args.lcm_url)
    except RuntimeError as exc:
        sys.exit("b21r_foxglove_bridge: cannot open LCM at %s (%s); a host-local udpm URL needs a multicast "
                 "route, e.g. ip route add 224.0.0.0/4 dev lo" % (args.lcm_url, exc))
    bridge = Bridge(args.world)
    try:
        server = foxglove.start_server(name="b21r", host=args.host, port=args.port)
    except Exception as exc:  # the SDK raises its own error types for a port in use
        sys.exit("b21r_foxglove_bridge: cannot serve on %s:%d (%s); give another --port" % (args.host, args.port, exc))
    lc.subscribe("B21R_.*", bridge.on_lcm)
    print("b21r_foxglove_bridge: serving LCM %s on ws://%s:%d (Foxglove: Open connection, Foxglove WebSocket)"
          % (args.lcm_url, args.host, server.port), flush=True)
    next_repeat = time.monotonic() + args.repeat_s
    fd = lc.fileno()
    try:
        while not stop:
            ready, _, _ = select.select([fd], [], [], 0.2)
            if ready:
                lc.handle()
            if time.monotonic() >= next_repeat:
                bridge.repeat()
                next_repeat = time.monotonic() + args.repeat_s
    finally:
        server.stop()
    print("b21r_foxglove_bridge: stopped after %d messages" % bridge.received, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
