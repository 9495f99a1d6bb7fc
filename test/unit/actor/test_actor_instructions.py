#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""actor.slice_instructions: the actor's costs counted in instructions (callgrind), not time, so
that the bound holds on a busy machine. actor_slices (beside this file) fills the ring with about
20,000 corridor-like transitions, then acts 1,000 times, drives one run (actions, records and a
kinematic step each) and does that run's between-run work in slices of BUDGET work units.

Claims (each fails the test when it does not hold):
  slice   every slice costs at most (BUDGET + ACTOR_WORK_QUERY) x ACTOR_INSTRUCTIONS_PER_UNIT
          instructions (actor/actor.h), the bound the header states
  act     one action costs at most 4,000 instructions (state dimension 4, 16 hidden units)
  whole   the whole work after the run is at most 1.5 billion instructions (the header's "about a
          third of a second of CPU")
usage: test_actor_instructions.py ACTOR_SLICES ACTOR_HEADER [BUDGET]"""
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile


def header_constant(path, name):
    m = re.search(r"#define %s (\d+)U" % name, open(path).read())
    if not m:
        sys.exit("FAIL: %s not in %s" % (name, path))
    return int(m.group(1))


def dumps(folder):
    """(trigger, instructions) of every callgrind dump, in order."""
    out = []
    for f in sorted(glob.glob(os.path.join(folder, "cg.out*")), key=lambda p: int(p.rsplit(".", 1)[-1])
                    if p.rsplit(".", 1)[-1].isdigit() else -1):
        text = open(f).read()
        trig = re.search(r"^desc: Trigger: Client Request: (.*)$", text, re.M)
        tot = re.search(r"^(?:summary|totals): (\d+)", text, re.M)
        if trig and tot:
            out.append((trig.group(1).strip(), int(tot.group(1))))
    return out


def main():
    exe, header = sys.argv[1:3]
    budget = int(sys.argv[3]) if len(sys.argv) > 3 else 1500
    if shutil.which("valgrind") is None:
        print("SKIP: valgrind is not installed (tools/debian-packages.txt lists it)")
        return 77
    per_unit = header_constant(header, "ACTOR_INSTRUCTIONS_PER_UNIT")
    query = header_constant(header, "ACTOR_WORK_QUERY")
    with tempfile.TemporaryDirectory(prefix="b21r-actor-cg-") as d:
        p = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                            "--callgrind-out-file=%s/cg.out" % d, exe, str(budget)],
                           capture_output=True, text=True)
        if p.returncode != 0:
            print("FAIL: %s exited %d\n%s" % (exe, p.returncode, p.stderr[-2000:]))
            return 1
        print(p.stdout.strip())
        ds = dumps(d)
    act = [n for t, n in ds if t == "act x1000"]
    run = [n for t, n in ds if t == "record run"]
    slices = [n for t, n in ds if t == "slice"]
    if len(act) != 1 or len(run) != 1 or not slices:
        print("FAIL: expected the act, run and slice dumps, got %s" % [t for t, _ in ds][:10])
        return 1
    bound = (budget + query) * per_unit
    worst = max(slices)
    ordered = sorted(slices)
    median = ordered[len(ordered) // 2]
    total = sum(slices)
    per_act = act[0] / 1000.0
    print("one action: %.0f instructions; the run (actions, records, kinematics): %d instructions" % (per_act, run[0]))
    print("between runs: %d slices of budget %d units, instructions per slice: median %d, largest %d "
          "(bound %d = (%d + %d) x %d); whole work %d instructions" %
          (len(slices), budget, median, worst, bound, budget, query, per_unit, total))
    ok = True
    for name, holds in (("slice", worst <= bound), ("act", per_act <= 4000), ("whole", total <= 1.5e9)):
        print("%-6s %s" % (name, "holds" if holds else "FAILS"))
        ok = ok and holds
    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
