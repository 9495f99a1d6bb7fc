#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_teleop: drive the B21r from a terminal (B21R_TELEOP) and send operator commands
(B21R_COMMAND) to b21r-controller over LCM.

Interactive (curses):
    b21r_teleop.py [--lcm-url URL]
      d            deadman: hold (the robot may move) / release (it stops within one tick)
      left/right   rotation velocity -/+ 0.1 rad/s      space  rotation 0
      up/down      translation -/+ 0.1 m/s (used only where the task does not set it)
      c            CONFIRM_START_POSE (the robot stands at the requested start pose)
      2            START_PHASE_TWO       p  PAUSE     r  RESUME      x  SHUTDOWN      q  quit
    Messages go out at 10 Hz while the deadman is held; without them the controller stops the
    robot (teleop_timeout_s) and reports "deadman released".
One command and exit:
    b21r_teleop.py --command START_PHASE_TWO|CONFIRM_START_POSE|PAUSE|RESUME|SHUTDOWN
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
generated types).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import sys
import time

import lcm

from b21r import command_t, teleop_t

COMMANDS = {"START_PHASE_TWO": command_t.START_PHASE_TWO, "CONFIRM_START_POSE": command_t.CONFIRM_START_POSE,
            "PAUSE": command_t.PAUSE, "RESUME": command_t.RESUME, "SHUTDOWN": command_t.SHUTDOWN}


def now_us():
    return int(time.time() * 1e6)


def send_command(lc, name, seq):
    m = command_t()
    m.utime = now_us()
    m.seq = seq
    m.command = COMMANDS[name]
    m.argument = 0
    lc.publish("B21R_COMMAND", m.encode())


def interactive(lc):
    import curses

    def run(scr):
        scr.nodelay(True)
        scr.keypad(True)
        deadman = False
        rot = 0.0
        trans = 0.0
        seq = int(time.time() * 1000)  # increasing across restarts of this tool
        cmd_seq = seq
        note = ""
        next_send = 0.0
        while True:
            k = scr.getch()
            if k in (ord("q"), 27):
                break
            if k == ord("d"):
                deadman = not deadman
            elif k == curses.KEY_LEFT:
                rot = round(rot - 0.1, 2)
            elif k == curses.KEY_RIGHT:
                rot = round(rot + 0.1, 2)
            elif k == ord(" "):
                rot = 0.0
            elif k == curses.KEY_UP:
                trans = round(trans + 0.1, 2)
            elif k == curses.KEY_DOWN:
                trans = round(trans - 0.1, 2)
            elif k in (ord("c"), ord("2"), ord("p"), ord("r"), ord("x")):
                name = {ord("c"): "CONFIRM_START_POSE", ord("2"): "START_PHASE_TWO", ord("p"): "PAUSE",
                        ord("r"): "RESUME", ord("x"): "SHUTDOWN"}[k]
                cmd_seq += 1
                send_command(lc, name, cmd_seq)
                note = "sent %s" % name
            t = time.time()
            if t >= next_send:
                next_send = t + 0.1
                if deadman:
                    seq += 1
                    m = teleop_t()
                    m.utime = now_us()
                    m.seq = seq
                    m.deadman = True
                    m.rotation_radps = rot
                    m.translation_mps = trans
                    lc.publish("B21R_TELEOP", m.encode())
            scr.erase()
            scr.addstr(0, 0, "B21r teleop   deadman %s   rotation %+.2f rad/s   translation %+.2f m/s" %
                       ("HELD" if deadman else "released", rot, trans))
            scr.addstr(2, 0, "d deadman  <- -> rotation  space zero  c confirm pose  2 phase two  p pause  "
                             "r resume  x shutdown  q quit")
            scr.addstr(4, 0, note)
            scr.refresh()
            time.sleep(0.02)

    curses.wrapper(run)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lcm-url", default=None)
    ap.add_argument("--command", choices=sorted(COMMANDS))
    args = ap.parse_args()
    lc = lcm.LCM(args.lcm_url) if args.lcm_url else lcm.LCM()
    if args.command:
        send_command(lc, args.command, int(time.time() * 1000))
        return 0
    interactive(lc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
