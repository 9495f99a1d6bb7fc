# SPDX-License-Identifier: MIT
"""pkgtest: shared helpers of the package tests: what the Debian package must hold, checked on an
installed tree (a DESTDIR staging folder, or a Debian root the package was installed into)."""
import os
import subprocess
import sys


def fail(msg):
    print("FAIL: " + msg, flush=True)
    sys.exit(1)


def note(msg):
    print(msg, flush=True)


# Every file the package must install (relative to the root), and the links of /usr/bin.
FILES = [
    "usr/bin/b21r-controller",
    "etc/b21r/b21r-controller.conf",
    "lib/systemd/system/b21r-controller.service",
    "usr/lib/sysusers.d/b21r-controller.conf",
    "usr/lib/b21r-controller/python/b21r_teleop.py",
    "usr/lib/b21r-controller/python/b21r_log.py",
    "usr/lib/b21r-controller/python/b21r_key.py",
    "usr/lib/b21r-controller/python/b21r_opauth.py",
    "usr/lib/b21r-controller/python/b21r_bootstrap.py",
    "usr/lib/b21r-controller/python/b21r_gamepads.toml",
    "usr/lib/b21r-controller/python/b21r/__init__.py",
    "usr/lib/b21r-controller/python/b21r/teleop_t.py",
    "usr/lib/b21r-controller/python/lcm/__init__.py",
    "usr/share/doc/b21r-controller/robot.md",
    "usr/share/doc/b21r-controller/lcm-python/COPYING",
]
LINKS = {"usr/bin/b21r-teleop": "../lib/b21r-controller/python/b21r_teleop.py",
         "usr/bin/b21r-log": "../lib/b21r-controller/python/b21r_log.py",
         "usr/bin/b21r-key": "../lib/b21r-controller/python/b21r_key.py"}
# The service's settings in the configuration file (on top of the reference's defaults).
CONF = ["rt_scheduler = fifo", "rt_lock_memory = true", "rt_prefault = true",
        'checkpoint_file = "/var/lib/b21r/hedger.ckpt"', 'operator_key_file = "/etc/b21r/operator.key"']
# What the unit must say (the list: real-time limits, restart, state, watchdog, user).
UNIT = ["Type=notify", "WatchdogSec=", "Restart=on-failure", "LimitRTPRIO=99", "LimitMEMLOCK=infinity",
        "StateDirectory=b21r", "User=b21r", "SuccessExitStatus=143",
        "ExecStart=/usr/bin/b21r-controller --config /etc/b21r/b21r-controller.conf"]


def check_tree(root):
    for f in FILES:
        if not os.path.isfile(os.path.join(root, f)):
            fail("the package lacks /%s" % f)
    for link, target in LINKS.items():
        p = os.path.join(root, link)
        if not os.path.islink(p) or os.readlink(p) != target:
            fail("/%s is not a link to %s" % (link, target))
        if not os.path.isfile(os.path.join(os.path.dirname(p), target)):
            fail("/%s dangles" % link)
    with open(os.path.join(root, "etc/b21r/b21r-controller.conf")) as f:
        conf = f.read().splitlines()
    for line in CONF:
        if line not in conf:
            fail("the configuration file lacks '%s'" % line)
    with open(os.path.join(root, "lib/systemd/system/b21r-controller.service")) as f:
        unit = f.read()
    for key in UNIT:
        if key not in unit:
            fail("the unit lacks '%s'" % key)
    note("files, links, configuration and unit: as required (%d files)" % len(FILES))


def run(cmd, **kw):
    return subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)
