#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""package.clean_root (label package; ctest --preset package; needs root and this machine's Debian
mirror): the amd64 package, built by cpack from this build, installed with
`apt-get install ./b21r-controller_*.deb` into a fresh Debian 12 root (debootstrap minbase, made
once and kept as a tarball in build/package-root/, with apt's downloads), then:
- the files, links, configuration and unit (pkgtest), the conffile registered with dpkg, the user
  b21r in group dialout, `systemd-analyze verify` in the root, every library of the controller found;
- the installed controller run as the unit runs it: systemd cannot be PID 1 in a chroot, so the
  unit's ExecStart= line is run by hand as its User=, with its LimitRTPRIO=/LimitMEMLOCK= (prlimit)
  and its State/LogsDirectory= made as systemd makes them, NOTIFY_SOCKET pointing at this test,
  against the emulator (this build's b21r-sim, lockstep, its pseudo-terminals seen through /dev):
  a short session (READY=1, STOPPING=1, exit 0, the checkpoint in /var/lib/b21r), a second one
  that resumes from it, and the installed log reader on the recorded log;
- apt-get purge keeps the learned state.
Where root cannot raise the hard resource limits (no CAP_SYS_RESOURCE, as in a container), the
sessions run with the configuration's rt_scheduler and rt_lock_memory turned off, and say so.
Usage: test_clean_root.py <build dir> <source dir> <b21r-sim> <world>"""
import glob
import os
import shlex
import shutil
import socket
import subprocess
import sys
import tempfile
import time

import pkgtest
from pkgtest import fail, note

SKIP = 77


def sh(cmd, **kw):
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, **kw)
    return r.returncode, r.stdout


def must(cmd, what, **kw):
    rc, out = sh(cmd, **kw)
    if rc != 0:
        fail("%s (exit %d):\n%s" % (what, rc, out[-4000:]))
    return out


def mirror():
    """The Debian 12 main archive this machine's apt uses."""
    out = must(["apt-cache", "policy"], "apt-cache policy")
    for line in out.splitlines():
        f = line.split()
        if len(f) >= 4 and f[2] == "bookworm/main" and f[3] == "amd64":
            return f[1]
    return "http://deb.debian.org/debian"


def base_tarball(cache):
    """A fresh debootstrap minbase root of Debian 12, as a tarball (made once)."""
    tar = os.path.join(cache, "bookworm-minbase-amd64.tar")
    if os.path.exists(tar):
        return tar
    work = os.path.join(cache, "debootstrap")
    shutil.rmtree(work, ignore_errors=True)
    t0 = time.time()
    must(["debootstrap", "--variant=minbase", "bookworm", work, mirror()], "debootstrap")
    must(["tar", "-C", work, "-cf", tar + ".new", "."], "tar")
    os.replace(tar + ".new", tar)
    shutil.rmtree(work, ignore_errors=True)
    note("made the Debian 12 minbase root in %.0f s (kept: %s)" % (time.time() - t0, tar))
    return tar


class Root:
    """A Debian root; commands run chrooted in a private mount namespace with /proc, the host's
    /dev (the emulator's pseudo-terminals) and apt's download cache mounted (gone with it)."""

    def __init__(self, path, archives):
        self.path = path
        self.archives = archives

    def cmd(self, argv, prefix=(), userspec=None):
        r = shlex.quote(self.path)
        mounts = ("mount -t proc proc %s/proc && mount --rbind /dev %s/dev && "
                  "mount --bind %s %s/var/cache/apt/archives" % (r, r, shlex.quote(self.archives), r))
        chroot = ["chroot"] + (["--userspec=" + userspec] if userspec else []) + [self.path]
        return ["unshare", "--mount", "--propagation", "private", "sh", "-c", mounts + ' && exec "$@"', "sh",
                *prefix, *chroot, *argv]

    def run(self, argv, what, **kw):
        return must(self.cmd(argv, **kw), what)


def unit_values(unit_text, key):
    return [line.split("=", 1)[1].strip() for line in unit_text.splitlines() if line.startswith(key + "=")]


def group_id(root, name):
    with open(os.path.join(root.path, "etc/group")) as f:
        for line in f:
            f = line.split(":")
            if f[0] == name:
                return int(f[2])
    fail("no group %s in the root" % name)


def notify_socket(path):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    os.chmod(path, 0o777)  # the service user sends to it
    s.settimeout(0.05)
    return s


def drain(sock):
    msgs = []
    while True:
        try:
            msgs.append(sock.recv(4096).decode())
        except socket.timeout:
            return msgs


def session(root, sim_exe, world, name, exec_start, prefix, settings, timeout):
    """One controller session under the unit's ExecStart= against a new emulator: (exit status,
    stderr, notifications)."""
    run_dir = os.path.join(root.path, "run/b21r-test")
    os.makedirs(run_dir, exist_ok=True)
    ctl = os.path.join(run_dir, name + ".ctl")
    endpoints = os.path.join(run_dir, name + ".endpoints")
    sock_path = os.path.join(run_dir, name + ".notify")
    sim_log = open(os.path.join(run_dir, name + ".sim.log"), "w")
    sim = subprocess.Popen([sim_exe, "--world", world, "--lockstep", "--seed", "1", "--control", ctl,
                            "--endpoints", endpoints], stdout=sim_log, stderr=subprocess.STDOUT)
    sock = notify_socket(sock_path)
    try:
        deadline = time.time() + 20
        while not (os.path.exists(endpoints) and os.path.getsize(endpoints) > 0):
            if sim.poll() is not None or time.time() > deadline:
                fail("b21r-sim did not start")
            time.sleep(0.05)
        with open(endpoints) as f:
            line = f.read().strip()
        # What udev does for serial lines: group dialout, 0660 (the emulator's pseudo-terminals are
        # root's), so that the service user reaches them through its group; the control socket too.
        dialout = group_id(root, "dialout")
        for kv in line.split():
            key, path = kv.split("=", 1)
            if key in ("laser", "base"):
                os.chown(path, -1, dialout)
                os.chmod(path, 0o660)
        os.chmod(ctl, 0o777)
        line = line.replace(root.path, "")  # the control socket as the root sees it
        args = exec_start + ["--endpoints", line] + [a for k, v in settings.items() for a in ("--set", "%s=%s" % (k, v))]
        inner = "cd /var/lib/b21r && exec env NOTIFY_SOCKET=/run/b21r-test/%s.notify %s" % (
            name, " ".join(shlex.quote(a) for a in args))
        p = subprocess.run(root.cmd(["sh", "-c", inner], prefix=prefix, userspec="b21r:b21r"),
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=timeout)
        time.sleep(0.1)
        return p.returncode, p.stderr, drain(sock)
    finally:
        sock.close()
        if sim.poll() is None:
            sim.terminate()
            sim.wait(10)
        sim_log.close()


def main():
    build, source, sim_exe, world = sys.argv[1:5]
    if os.geteuid() != 0:
        note("SKIP: needs root (debootstrap, chroot, mounts)")
        return SKIP
    for tool in ("debootstrap", "unshare", "chroot", "cpack", "prlimit"):
        if shutil.which(tool) is None:
            fail("%s is missing: run tools/setup.sh" % tool)
    t_start = time.time()
    out = must(["cpack", "--config", os.path.join(build, "CPackConfig.cmake")], "cpack", cwd=build)
    debs = sorted(glob.glob(os.path.join(build, "packages", "b21r-controller_*_amd64.deb")), key=os.path.getmtime)
    if not debs:
        fail("cpack made no amd64 package:\n%s" % out)
    deb = debs[-1]
    note("package: %s (%d KiB)" % (os.path.basename(deb), os.path.getsize(deb) // 1024))

    cache = os.path.join(source, "build", "package-root")
    archives = os.path.join(cache, "apt-archives")
    os.makedirs(os.path.join(archives, "partial"), exist_ok=True)
    tar = base_tarball(cache)
    d = tempfile.mkdtemp(prefix="run-", dir=cache)
    ok = False
    try:
        root = Root(os.path.join(d, "root"), archives)
        os.makedirs(root.path)
        must(["tar", "-C", root.path, "-xf", tar], "unpacking the Debian root")
        shutil.copy("/etc/resolv.conf", os.path.join(root.path, "etc/resolv.conf"))
        with open(os.path.join(root.path, "usr/sbin/policy-rc.d"), "w") as f:
            f.write("#!/bin/sh\nexit 101\n")  # nothing starts services in the chroot
        os.chmod(os.path.join(root.path, "usr/sbin/policy-rc.d"), 0o755)
        shutil.copy(deb, os.path.join(root.path, "tmp"))
        t0 = time.time()
        root.run(["sh", "-c", "apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "
                  "--no-install-recommends ./tmp/%s" % os.path.basename(deb)], "apt-get install ./%s" % os.path.basename(deb))
        note("apt-get install ./%s into a fresh Debian 12 minbase root: %.0f s" % (os.path.basename(deb), time.time() - t0))

        pkgtest.check_tree(root.path)
        conffiles = root.run(["dpkg-query", "-W", "-f=${Conffiles}", "b21r-controller"], "dpkg-query")
        if "/etc/b21r/b21r-controller.conf" not in conffiles:
            fail("/etc/b21r/b21r-controller.conf is not a conffile: %r" % conffiles)
        ident = root.run(["id", "b21r"], "id b21r")
        if "(dialout)" not in ident or "(b21r)" not in ident:
            fail("user b21r: %s" % ident)
        verify = root.run(["systemd-analyze", "verify", "--man=no", "/lib/systemd/system/b21r-controller.service"],
                          "systemd-analyze verify in the root")
        if verify.strip():
            fail("systemd-analyze verify in the root:\n%s" % verify)
        libs = root.run(["ldd", "/usr/bin/b21r-controller"], "ldd")
        if "not found" in libs:
            fail("libraries missing for the controller:\n%s" % libs)
        note("conffile registered, %s, systemd-analyze verify clean, every library found" % ident.strip())

        with open(os.path.join(root.path, "lib/systemd/system/b21r-controller.service")) as f:
            unit = f.read()
        exec_start = shlex.split(unit_values(unit, "ExecStart")[0])
        rtprio = unit_values(unit, "LimitRTPRIO")[0]
        memlock = unit_values(unit, "LimitMEMLOCK")[0].replace("infinity", "unlimited")
        for key in ("StateDirectory", "LogsDirectory"):
            for name in unit_values(unit, key):
                base = "/var/lib/" if key == "StateDirectory" else "/var/log/"
                root.run(["install", "-d", "-o", "b21r", "-g", "b21r", "-m", "0750", base + name], key)
        prefix = ["prlimit", "--rtprio=%s:%s" % (rtprio, rtprio), "--memlock=%s:%s" % (memlock, memlock), "--"]
        settings = {"lockstep": "true", "lcm_url": "none", "phase_one_runs": 3, "phase_two_runs": 1,
                    "eval_every_runs": 4, "eval_starts": 2, "hedger_replay_passes": 2,
                    "log_file": "/var/log/b21r/first.lcmlog"}
        if sh(prefix + ["true"])[0] != 0:
            prefix = []
            settings.update(rt_scheduler="other", rt_lock_memory="false")
            note("this machine's root cannot raise RLIMIT_RTPRIO/RLIMIT_MEMLOCK (no CAP_SYS_RESOURCE): the "
                 "sessions run with rt_scheduler = other and rt_lock_memory = false")
        else:
            note("the unit's limits: LimitRTPRIO=%s, LimitMEMLOCK=%s (prlimit)" % (rtprio, memlock))

        t0 = time.time()
        rc, err, msgs = session(root, sim_exe, world, "first", exec_start, prefix, settings, 600)
        if rc != 0:
            fail("the installed controller: exit status %d:\n%s" % (rc, err))
        if not any(m.startswith("READY=1") for m in msgs) or not any(m.startswith("STOPPING=1") for m in msgs):
            fail("notifications: %r" % msgs)
        ckpt = os.path.join(root.path, "var/lib/b21r/hedger.ckpt")
        if not os.path.exists(ckpt) or os.stat(ckpt).st_uid != int(ident.split("=")[1].split("(")[0]):
            fail("no checkpoint of user b21r in /var/lib/b21r:\n%s" % err)
        note("session 1 (ExecStart= as user b21r): exit 0, %s, checkpoint %d bytes, %.0f s"
             % (" / ".join(m.split("\n")[0] for m in msgs), os.path.getsize(ckpt), time.time() - t0))
        rc, err, msgs = session(root, sim_exe, world, "second", exec_start, prefix,
                                dict(settings, eval_starts=1, log_file="/var/log/b21r/second.lcmlog"), 600)
        if rc != 0 or "resumed from /var/lib/b21r/hedger.ckpt" not in err:
            fail("session 2 did not resume from the checkpoint (exit %d):\n%s" % (rc, err))
        note("session 2 resumed from /var/lib/b21r/hedger.ckpt")
        runs = root.run(["b21r-log", "/var/log/b21r/first.lcmlog", "--runs"], "the installed b21r-log")
        if len([ln for ln in runs.splitlines() if ln.startswith("run ")]) != 6:
            fail("b21r-log --runs on the first session (4 training and 2 evaluation runs) printed:\n%s" % runs)
        note("b21r-log --runs on the first session's log: 6 runs")

        root.run(["sh", "-c", "DEBIAN_FRONTEND=noninteractive apt-get purge -y -qq b21r-controller"], "apt-get purge")
        if not os.path.exists(ckpt) or os.path.exists(os.path.join(root.path, "usr/bin/b21r-controller")):
            fail("after apt-get purge: the learned state must stay and the program go")
        note("apt-get purge: program removed, learned state kept")
        ok = True
    finally:
        if ok:
            shutil.rmtree(d, ignore_errors=True)
        else:
            note("root kept in %s" % d)
    note("package.clean_root: %.0f s" % (time.time() - t_start))
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
