#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.policy_map: tools/b21r_policy_map.py on real checkpoints. Short lockstep sessions
(corridor with one phase-two run; obstacles and doorway in phase one) write checkpoints; the
tool, run as an operator runs it, writes policy_map_<task>.png (a real picture of the expected
size) and its numbers (JSON):
- on a checkpoint whose store is empty (the corridor file's controller section with a fresh
  learner's bytes, written in the checkpoint format of fw/checkpoint.h) every reachable cell is
  HEDGER's unknown region, and the picture differs from the learned one;
- on the learned checkpoints part of the slice is known, the teacher's command is the example
  policy at its nominal gain (corridor: 1.25 x the target angle), the learned command equals the
  controller's policy (HEDGER's greedy action, clamped) at the cells checked, and the header says
  what the checkpoint holds;
- a damaged file is refused with the checkpoint reader's reason.
usage: test_policy_map.py CONTROLLER SIM REPO"""
import json
import math
import os
import struct
import subprocess
import sys
import zlib

import gymnasium
import numpy as np
from PIL import Image

import b21r_learn
import fwtest


def write_checkpoint(path, meta, payload):
    """A checkpoint file as fw_checkpoint_write lays it out (fw/checkpoint.h)."""
    head = b"B21RCKPT" + struct.pack("<IIQQII", 1, 48, len(meta), len(payload), zlib.crc32(meta), zlib.crc32(payload))
    head += struct.pack("<I", 0)
    head += struct.pack("<I", zlib.crc32(head))
    with open(path, "wb") as f:
        f.write(head + meta + payload)


def run_tool(repo, ckpt, out):
    p = subprocess.run([os.path.join(repo, "tools", "b21r_policy_map.py"), "--checkpoint", ckpt, "--out", out,
                        "--grid", "25"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=300,
                       env={"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root")})
    return p.returncode, p.stdout


def check_picture(out, task, want_size=(1920, 416)):
    png = os.path.join(out, "policy_map_%s.png" % task)
    with Image.open(png) as img:
        if img.size != want_size:
            fwtest.fail("%s is %dx%d, expected %dx%d" % (png, img.size[0], img.size[1], *want_size))
        colours = img.convert("RGB").getcolors(1 << 20)
        if colours is None or len(colours) < 50:
            fwtest.fail("%s looks empty (%s colours)" % (png, len(colours) if colours else "?"))
        data = np.asarray(img.convert("RGB"))
    with open(os.path.join(out, "policy_map_%s.json" % task)) as f:
        return json.load(f), data


def main():
    controller, sim_exe, repo = sys.argv[1:4]
    d = fwtest.workdir("policy-map")
    ok = False
    try:
        ckpts = {}
        for task, world, settings in (
                ("corridor", "corridor10.world", {"phase_one_runs": 6, "phase_two_runs": 1, "eval_every_runs": 100}),
                ("obstacles", "obstacle1.world", {"task": "obstacles", "phase_one_runs": 6, "phase_two_runs": 0,
                                                   "eval_every_runs": 100}),
                ("doorway", "doorway.world", {"task": "doorway", "phase_one_runs": 6, "phase_two_runs": 0,
                                              "eval_every_runs": 100})):
            sim = fwtest.Sim(sim_exe, os.path.join(repo, "sim", "worlds", world), d, task)
            ckpt = os.path.join(d, task + ".ckpt")
            rc, err, _ = fwtest.run_controller(controller, sim, d, task, dict(settings, checkpoint_file=ckpt), 300)
            sim.close()
            if rc != 0 or not os.path.exists(ckpt):
                fwtest.fail("%s session: exit %d, no checkpoint\n%s" % (task, rc, err[-2000:]))
            ckpts[task] = ckpt

        # Learned checkpoints.
        pictures = {}
        for task, ckpt in ckpts.items():
            out = os.path.join(d, task)
            rc, text = run_tool(repo, ckpt, out)
            if rc != 0:
                fwtest.fail("b21r_policy_map.py on the %s checkpoint: exit %d\n%s" % (task, rc, text))
            s, pictures[task] = check_picture(out, task)
            meta, payload = b21r_learn.read_checkpoint(ckpt)
            prog = b21r_learn.read_checkpoint_progress(meta)
            if s["task"] != task or s["training_runs"] != prog["training_runs"] or s["phase"] != prog["phase"]:
                fwtest.fail("%s: the map's header %s does not say what the checkpoint holds %s" % (task, s, prog))
            if not 0.0 < s["unknown_fraction"] < 0.95 or s["learned_closer_fraction"] is None:
                fwtest.fail("%s: unknown fraction %.2f on a learned store" % (task, s["unknown_fraction"]))
            fwtest.note("%s: %s" % (task, text.strip()))
        # The corridor's cells, recomputed here: the teacher and the learned policy as the controller drives it.
        import b21r_policy_map as pm
        h, prog, cfg = pm.load(ckpts["corridor"], {})
        r = pm.compute(h, prog, cfg, 25, 5.0)
        env = gymnasium.make("B21rCorridor-v0", backend="kinematic").unwrapped
        spec = env.task_spec
        checked = 0
        for i in range(0, 25, 3):
            for j in range(0, 25, 3):
                if not r["reachable"][i, j]:
                    continue
                angle = r["y"][i]
                if abs(r["teacher"][i, j] - max(-1.0, min(1.0, 1.25 * angle))) > 0.02:
                    fwtest.fail("teacher's command %.3f at target angle %.2f, expected 1.25 x it" %
                                (r["teacher"][i, j], angle))
                if r["unknown"][i, j]:
                    continue
                # The slice's cell as a pose; the learned command is the policy's at the state with its own
                # last command (r["command"]).
                offset = (0.5 - r["x"][j]) * spec["width_m"]
                phi = angle + math.atan2(offset, spec.get("lookahead_m", 2.0))
                obs, _ = env.reset(seed=1, options={"pose": (spec["length_m"] - 5.0, offset, -phi)})
                feats = np.asarray(obs, dtype=np.float64)
                a = r["learned"][i, j]
                g, _, _, known = h.greedy(np.append(feats, r["command"][i, j]))
                want = max(-1.0, min(1.0, g)) if known else None
                if want is None or abs(want - a) > 1e-9:
                    fwtest.fail("learned command %.3f at cell (%d, %d); the controller's policy there gives %s" %
                                (a, i, j, want))
                checked += 1
        if checked == 0:
            fwtest.fail("no known cell checked")
        fwtest.note("corridor: teacher = 1.25 x target angle, learned = the greedy action at %d cells" % checked)

        # An empty store: all unknown.
        meta, _ = b21r_learn.read_checkpoint(ckpts["corridor"])
        empty = b21r_learn.Hedger(**b21r_learn.controller_learner_config("corridor")).save()
        write_checkpoint(os.path.join(d, "empty.ckpt"), meta, empty)
        rc, text = run_tool(repo, os.path.join(d, "empty.ckpt"), os.path.join(d, "empty"))
        if rc != 0:
            fwtest.fail("b21r_policy_map.py on an empty store: exit %d\n%s" % (rc, text))
        s, img = check_picture(os.path.join(d, "empty"), "corridor")
        if s["unknown_fraction"] != 1.0 or s["unknown_cells"] != s["reachable_cells"] or s["reachable_cells"] == 0:
            fwtest.fail("empty store: %d of %d reachable cells unknown" % (s["unknown_cells"], s["reachable_cells"]))
        if np.array_equal(img, pictures["corridor"]):
            fwtest.fail("the empty store's picture equals the learned one")
        fwtest.note("empty store: all %d reachable cells unknown (hatched)" % s["reachable_cells"])

        # A damaged file.
        with open(ckpts["corridor"], "rb") as f:
            data = bytearray(f.read())
        data[100] ^= 0xFF
        bad = os.path.join(d, "bad.ckpt")
        with open(bad, "wb") as f:
            f.write(data)
        rc, text = run_tool(repo, bad, os.path.join(d, "bad"))
        if rc == 0 or "corrupt" not in text or "Traceback" in text:
            fwtest.fail("a damaged checkpoint: exit %d\n%s" % (rc, text))
        fwtest.note("damaged file refused: %s" % text.strip().splitlines()[-1])
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
