# SPDX-License-Identifier: MIT
"""xdisplay: a virtual X display (Xvfb) for the lcm-spy tests, screenshots of it (python-xlib +
Pillow), and lcm-spy's channel table as its accessibility tree shows it (B21rSpyProbe, a Java
agent built into build/<preset>/java/b21r-spy-probe.jar)."""
import os
import subprocess
import time

import fwtest


class Xvfb:
    """Xvfb on the first free display number (it picks one itself: -displayfd)."""

    def __init__(self, workdir, size="1280x1024x24"):
        r, w = os.pipe()
        self.log = open(os.path.join(workdir, "xvfb.log"), "w")
        self.proc = subprocess.Popen(["Xvfb", "-displayfd", str(w), "-screen", "0", size, "-nolisten", "tcp"],
                                     pass_fds=(w,), stdout=self.log, stderr=subprocess.STDOUT)
        os.close(w)
        with os.fdopen(r) as f:
            line = f.readline().strip()
        if not line.isdigit():
            fwtest.fail("Xvfb did not start (see %s)" % self.log.name)
        self.display = ":" + line

    def close(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def screenshot(display, path):
    """The whole screen as a PIL image, also saved to path (PNG)."""
    from PIL import Image
    from Xlib import X, display as xdisplay

    d = xdisplay.Display(display)
    try:
        root = d.screen().root
        g = root.get_geometry()
        raw = root.get_image(0, 0, g.width, g.height, X.ZPixmap, 0xFFFFFFFF)
        img = Image.frombytes("RGB", (g.width, g.height), raw.data, "raw", "BGRX")
    finally:
        d.close()
    img.save(path)
    return img


def spy_env(display, probe_jar, probe_out):
    """The environment that starts lcm-spy on the display with the probe loaded."""
    env = dict(os.environ, DISPLAY=display)
    env["JDK_JAVA_OPTIONS"] = "-javaagent:%s=%s" % (probe_jar, probe_out)
    return env


def read_probe(path):
    """(windows [(title, bounds)], tables [{"bounds": (x, y, w, h), "header": [...], "rows": [[...]]}])."""
    windows, tables = [], []
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except FileNotFoundError:
        return windows, tables
    for line in lines:
        parts = line.split("\t")
        if parts[0] == "window":
            windows.append((parts[1], parts[2] if len(parts) > 2 else "hidden"))
        elif parts[0] == "table":
            b = parts[1].split()
            tables.append({"bounds": tuple(int(x) for x in b) if len(b) == 4 else None, "header": [], "rows": []})
        elif parts[0] == "header" and tables:
            tables[-1]["header"] = parts[1:]
        elif parts[0] == "row" and tables:
            tables[-1]["rows"].append(parts[1:])
    return windows, tables


def channel_table(path):
    """lcm-spy's channel table as {channel: {column: value}}, or None before the window shows."""
    windows, tables = read_probe(path)
    for t in tables:
        if "Channel" in t["header"] and "Type" in t["header"]:
            return {r[0]: dict(zip(t["header"], r)) for r in t["rows"] if r}, t["bounds"]
    return None


def wait_channels(path, channels, timeout, procs=()):
    """Waits until lcm-spy's table shows every channel with a message count > 0; returns the
    table and its bounds. Fails when a process in procs ends first or the time runs out."""
    deadline = time.time() + timeout
    last = None
    while time.time() < deadline:
        got = channel_table(path)
        if got is not None:
            last = got
            rows = got[0]
            if all(ch in rows and rows[ch].get("Num Msgs", "0").strip() not in ("", "0") for ch in channels):
                return got
        for name, p in procs:
            if p.poll() is not None:
                fwtest.fail("%s exited (%s) before lcm-spy showed %s; its table: %s" % (name, p.returncode,
                                                                                      channels, last))
        time.sleep(0.25)
    fwtest.fail("lcm-spy did not show %s within %d s; its table: %s" % (sorted(channels), timeout, last))


def check_decoded(rows, prefix="B21R_"):
    """Every product channel decoded: a type name (not '?? <fingerprint>') and no undecodable message."""
    ours = {ch: r for ch, r in rows.items() if ch.startswith(prefix)}
    if not ours:
        fwtest.fail("lcm-spy shows no %s channel: %s" % (prefix, sorted(rows)))
    for ch, r in ours.items():
        if r.get("Type", "").startswith("??") or not r.get("Type", "").endswith("_t"):
            fwtest.fail("lcm-spy cannot decode %s: type column '%s' (is b21r-types.jar on its class path?)" %
                        (ch, r.get("Type")))
        if r.get("Undecodable", "0").strip() != "0":
            fwtest.fail("lcm-spy counts %s undecodable messages on %s" % (r.get("Undecodable"), ch))
    return ours


def check_screenshot(img, table_bounds, n_rows):
    """The screenshot shows a window (not a blank screen) and, inside the table's bounds, a line
    of text per row (dark pixels on the table's background)."""
    colours = img.getcolors(1 << 20)
    if colours is None or len(colours) < 8:
        fwtest.fail("the screenshot is blank (%s colours)" % (len(colours) if colours else "too many"))
    x, y, w, h = table_bounds
    crop = img.crop((x, y, x + w, y + h)).convert("L")
    if crop.size[0] < 100 or crop.size[1] < 8:
        fwtest.fail("lcm-spy's table is %dx%d pixels on screen" % crop.size)
    width, height = crop.size
    px = crop.load()
    inked = [sum(1 for i in range(width) if px[i, j] < 128) for j in range(height)]
    # Text rows: runs of scan lines with dark pixels, separated by blank ones.
    lines, inside = 0, False
    for n in inked:
        if n > 3 and not inside:
            lines += 1
        inside = n > 3
    if lines < n_rows:
        fwtest.fail("the table's area on the screenshot shows %d lines of text for %d rows" % (lines, n_rows))
    return len(colours), lines
