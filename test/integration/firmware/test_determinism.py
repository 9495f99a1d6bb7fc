#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.determinism_<base>: the same run twice (fresh emulator, same seeds, lockstep) gives
bit-identical experience streams: the controller's --experience-log files are byte-identical
(SHA-256), and a different controller seed gives a different stream.
usage: test_determinism.py CONTROLLER SIM WORLD rflex|canopen"""
import hashlib
import os
import sys

import fwtest
from b21r_log import experience_gaps, read_log


def one_run(controller, sim_exe, world, base, d, name, seed):
    sim = fwtest.Sim(sim_exe, world, d, name, base=base, seed=1)
    try:
        exp = os.path.join(d, name + ".experiences.lcmlog")
        settings = {"phase_one_runs": 3, "phase_two_runs": 2, "eval_every_runs": 5, "eval_starts": 2,
                    "seed": seed, "experience_log_file": exp}
        rc, err, _ = fwtest.run_controller(controller, sim, d, name, settings, timeout=300)
        if rc != 0:
            fwtest.fail("%s: controller exit status %d:\n%s" % (name, rc, err))
    finally:
        sim.close()
    with open(exp, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    exps = [m for _, _, m in read_log(exp)]
    if not exps or experience_gaps(exps):
        fwtest.fail("%s: %d experiences, gaps %s" % (name, len(exps), experience_gaps(exps)[:5]))
    fwtest.note("%s: %d experiences, sha256 %s" % (name, len(exps), digest))
    return digest


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    d = fwtest.workdir("determinism-" + base)
    ok = False
    try:
        a = one_run(controller, sim_exe, world, base, d, "first", 7)
        b = one_run(controller, sim_exe, world, base, d, "second", 7)
        c = one_run(controller, sim_exe, world, base, d, "other-seed", 8)
        if a != b:
            fwtest.fail("the same run twice gave different experience streams")
        if a == c:
            fwtest.fail("a different seed gave the same stream (the seed is not used?)")
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
