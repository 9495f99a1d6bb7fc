#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.lockstep_load (label rt): lockstep never depends on wall time. The same learning
schedule and seed run twice against a fresh emulator in lockstep, once on an idle machine and once
with stress-ng loading every core; the two experience streams must be bit-identical (SHA-256 of
the controller's --experience-log).
usage: test_lockstep_load.py CONTROLLER SIM WORLD"""
import hashlib
import os
import sys

import fwtest
import rtload
from b21r_log import experience_gaps, read_log


def one_run(controller, sim_exe, world, d, name):
    sim = fwtest.Sim(sim_exe, world, d, name, seed=1)
    try:
        exp = os.path.join(d, name + ".experiences.lcmlog")
        settings = {"phase_one_runs": 3, "phase_two_runs": 2, "eval_every_runs": 5, "eval_starts": 2, "seed": 11,
                    "experience_log_file": exp}
        rc, err, _ = fwtest.run_controller(controller, sim, d, name, settings, timeout=900)
        if rc != 0:
            fwtest.fail("%s: controller exit status %d:\n%s" % (name, rc, err))
    finally:
        sim.close()
    exps = [m for _, _, m in read_log(exp)]
    if not exps or experience_gaps(exps):
        fwtest.fail("%s: %d experiences, gaps %s" % (name, len(exps), experience_gaps(exps)[:5]))
    with open(exp, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    fwtest.note("%s: %d experiences, sha256 %s" % (name, len(exps), digest))
    return digest


def main():
    controller, sim_exe, world = sys.argv[1:4]
    d = fwtest.workdir("lockstep-load")
    ok = False
    try:
        idle = one_run(controller, sim_exe, world, d, "idle")
        stress = rtload.start_stress(1200, os.path.join(d, "stress.log"))
        try:
            loaded = one_run(controller, sim_exe, world, d, "loaded")
        finally:
            rtload.stop(stress)
        if idle != loaded:
            fwtest.fail("the run under load gave a different experience stream")
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
