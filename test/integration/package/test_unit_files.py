#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""package.unit_files: the package's install rules into a staging folder (DESTDIR, component
robot), then:
- every file, link, the service's settings in /etc/b21r/b21r-controller.conf and the unit's keys;
- `systemd-analyze verify` on the unit, over this machine's own units, passes without a word
  (it returns 0 on settings it ignores: any output fails the test);
- the controller accepts the installed configuration (--print-config), and the installed teleop
  tool and log reader run on this machine's /usr/bin/python3 with the shipped LCM binding and types
  (no venv).
Usage: test_unit_files.py <build dir> <b21r-controller>"""
import os
import shutil
import sys
import tempfile

import pkgtest
from pkgtest import fail, note, run


def main():
    build, controller = sys.argv[1:3]
    d = tempfile.mkdtemp(prefix="b21r-unit-files-")
    ok = False
    try:
        root = os.path.join(d, "root")
        r = run(["cmake", "--install", build, "--component", "robot", "--prefix", "/usr"],
                env=dict(os.environ, DESTDIR=root))
        if r.returncode != 0:
            fail("cmake --install: %s" % r.stdout)
        pkgtest.check_tree(root)

        # systemd-analyze verify needs the system's units (sysinit.target, ...) beside ours.
        analyze = shutil.which("systemd-analyze")
        if analyze is None:
            fail("systemd-analyze is missing: run tools/setup.sh (Debian package systemd)")
        units = os.path.join(root, "lib/systemd/system")
        for name in os.listdir("/lib/systemd/system"):
            src = os.path.join("/lib/systemd/system", name)
            dst = os.path.join(units, name)
            if not os.path.lexists(dst):
                if os.path.isdir(src) and not os.path.islink(src):
                    shutil.copytree(src, dst, symlinks=True)
                else:
                    shutil.copy2(src, dst, follow_symlinks=False)
        r = run([analyze, "verify", "--man=no", "--root=" + root, "/lib/systemd/system/b21r-controller.service"])
        if r.returncode != 0 or r.stdout.strip():
            fail("systemd-analyze verify (exit %d):\n%s" % (r.returncode, r.stdout))
        note("systemd-analyze verify: clean")

        conf = os.path.join(root, "etc/b21r/b21r-controller.conf")
        r = run([controller, "--config", conf, "--print-config"])
        if r.returncode != 0 or 'checkpoint_file = "/var/lib/b21r/hedger.ckpt"' not in r.stdout:
            fail("the controller refuses the installed configuration (exit %d):\n%s" % (r.returncode, r.stdout[-2000:]))
        note("the controller accepts /etc/b21r/b21r-controller.conf")

        env = {"PATH": "/usr/bin:/bin", "HOME": d}  # a plain environment: no venv, no PYTHONPATH
        for tool, want in (("b21r-log", "--gaps"), ("b21r-teleop", "--command"), ("b21r-key", "create")):
            r = run(["/usr/bin/python3", os.path.join(root, "usr/bin", tool), "--help"], env=env)
            if r.returncode != 0 or want not in r.stdout:
                fail("installed %s --help (exit %d):\n%s" % (tool, r.returncode, r.stdout[-2000:]))
        r = run(["/usr/bin/python3", "-c", "import sys; sys.path.insert(0, sys.argv[1]); import lcm, b21r; "
                 "l = lcm.LCM('memq://'); l.publish('X', b21r.command_t().encode()); print('lcm ok')",
                 os.path.join(root, "usr/lib/b21r-controller/python")], env=env)
        if r.returncode != 0 or "lcm ok" not in r.stdout:
            fail("the shipped LCM binding does not work on /usr/bin/python3:\n%s" % r.stdout)
        note("b21r-log, b21r-teleop, b21r-key and the LCM binding run on /usr/bin/python3")
        ok = True
    finally:
        if ok:
            shutil.rmtree(d, ignore_errors=True)
        else:
            note("files kept in %s" % d)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
