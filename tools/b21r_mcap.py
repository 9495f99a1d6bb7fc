#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_mcap: converts one of the product's LCM event logs (the controller's --log or
--experience-log file, an lcm-logger recording) to MCAP, which Foxglove opens without plugins.

    b21r_mcap.py LOG [--out FILE.mcap] [--world FILE] [--force]

Topics and schemas (tools/b21r_foxglove.py): the laser as foxglove.LaserScan, the odometry and
the task-frame pose as foxglove.PoseInFrame with foxglove.FrameTransforms (world -> odom ->
base_link -> laser), the run's path as foxglove.PosesInFrame, walls, obstacles and the goal as a
foxglove.SceneUpdate, the commanded velocities as JSON shaped like geometry_msgs/Twist, and every
product message (experience, run, evaluation block, status, configuration, teleop, command) as
JSON with its JSON Schema; each message at its LCM receive time (the event's timestamp). The
task-frame start of every run comes from its B21R_RUN record where the log has one (the
controller's --log), else from the run's first state. Default output: LOG with .mcap. Messages
of types other than the product's are skipped (and counted).
Runs from a plain shell after tools/setup.sh and a build.
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import os
import sys

import lcm
from mcap.writer import CompressionType, Writer

import b21r
import b21r_foxglove as bf
from b21r_log import FINGERPRINTS


def known_starts(events):
    """run_id -> task-frame start pose, from the log's B21R_RUN records (a controller restart,
    whose run ids start again, keeps the later record)."""
    return {m.run_id: (m.start_x_m, m.start_y_m, m.start_theta_rad) for _, ch, m in events if isinstance(m, b21r.run_t)}


def read_events(path):
    """(events [(timestamp_us, channel, message)], skipped count) of a log, in file order."""
    events, skipped = [], 0
    log = lcm.EventLog(path, "r")
    try:
        for ev in log:
            t = FINGERPRINTS.get(bytes(ev.data[:8]))
            if t is None:
                skipped += 1
                continue
            events.append((ev.timestamp, ev.channel, t.decode(ev.data)))
    finally:
        log.close()
    return events, skipped


class McapSink:
    """Writes converted messages: one schema and channel per topic, registered on first use."""

    def __init__(self, stream):
        self.w = Writer(stream, compression=CompressionType.ZSTD)
        self.w.start(profile="", library="b21r_mcap")
        self.kinds = bf.all_topics()
        self.channels = {}
        self.counts = {}

    def channel(self, topic):
        if topic not in self.channels:
            kind, spec = self.kinds[topic]
            if kind == "protobuf":
                s = spec.get_schema()
                sid = self.w.register_schema(name=s.name, encoding="protobuf", data=bytes(s.data))
                self.channels[topic] = self.w.register_channel(topic=topic, message_encoding="protobuf", schema_id=sid)
            else:
                import json
                sid = self.w.register_schema(name=spec["title"], encoding="jsonschema", data=json.dumps(spec).encode())
                self.channels[topic] = self.w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        return self.channels[topic]

    def write(self, topic, message, t_ns):
        cid = self.channel(topic)
        self.w.add_message(channel_id=cid, log_time=t_ns, publish_time=t_ns, sequence=self.counts.get(topic, 0),
                           data=bf.encode(self.kinds[topic][0], message))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def finish(self, metadata):
        self.w.add_metadata("b21r", metadata)
        self.w.finish()


def convert(log_path, out_path, world_file=None):
    """Converts log_path into out_path; returns (counts per topic, events read, events skipped)."""
    events, skipped = read_events(log_path)
    task = next((m.task for _, _, m in events if isinstance(m, (b21r.config_t, b21r.experience_t))), bf.TASK_CORRIDOR)
    conv = bf.Converter(b21r_bootstrap.REPO, world_file=world_file, known_starts=known_starts(events),
                        default_task=task)
    tmp = out_path + ".tmp"
    with open(tmp, "wb") as f:
        sink = McapSink(f)
        for t_us, channel, msg in events:
            t_ns = int(t_us) * 1000
            for topic, m in conv.convert(channel, msg, t_ns):
                sink.write(topic, m, t_ns)
        sink.finish({"source": os.path.basename(log_path), "events": str(len(events)), "skipped": str(skipped)})
    os.replace(tmp, out_path)
    return sink.counts, len(events), skipped


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", help="LCM event log")
    ap.add_argument("--out", help="MCAP file to write (default: LOG with .mcap)")
    ap.add_argument("--world", help="b21r-sim world file to draw (default: the task's: the corridor of the "
                                    "recorded length, or the task's world as declared, with the recorded task_params)")
    ap.add_argument("--force", action="store_true", help="replace an existing output file")
    args = ap.parse_args()
    out = args.out or os.path.splitext(args.log)[0] + ".mcap"
    if os.path.exists(out) and not args.force:
        sys.exit("b21r_mcap: %s exists; give --force to replace it (or --out another file)" % out)
    try:
        counts, n, skipped = convert(args.log, out, args.world)
    except IOError as exc:
        sys.exit("b21r_mcap: cannot convert %s: %s" % (args.log, exc))
    print("%s: %d LCM messages -> %d MCAP messages on %d topics%s" % (
        out, n, sum(counts.values()), len(counts), ", %d of other types skipped" % skipped if skipped else ""))
    for topic in sorted(counts):
        print("  %-20s %7d" % (topic, counts[topic]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
