#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_key: create and identify the operator key that signs B21R_TELEOP and B21R_COMMAND
(docs/robot.md, "Network and security").

    b21r_key.py create [--force] [FILE]   a new random 32-byte key, written as 64 hex digits with
                                          mode 600 (FILE's folder made with mode 700 when missing);
                                          an existing FILE is kept unless --force replaces it
    b21r_key.py id [FILE]                 check FILE as the controller does and print its key id

FILE: default $B21R_OPERATOR_KEY, else ~/.config/b21r/operator.key (where b21r_teleop.py and
b21r_session.py look), else /etc/b21r/operator.key when it exists. On the robot: run `create` as the
user of the controller (root), e.g. b21r_key.py create /etc/b21r/operator.key, and set the
controller's operator_key_file to it; give each operator a copy (mode 600) over a channel you
trust. Rotate: create --force, restart the controller, hand out the new copy: the old key stops
working at once. The key id (the first 8 bytes of its SHA-256) names a key without revealing it;
the controller prints its key's id at start-up and announces it on B21R_SESSION.
Needs only Python's standard library.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import b21r_opauth  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("create", help="write a new random key")
    c.add_argument("--force", action="store_true", help="replace an existing key file")
    c.add_argument("file", nargs="?")
    i = sub.add_parser("id", help="check a key file and print its key id")
    i.add_argument("file", nargs="?")
    args = ap.parse_args(argv)
    path = b21r_opauth.find_key_path(args.file)
    try:
        if args.what == "create":
            key = b21r_opauth.create_key(path, replace=args.force)
            print("b21r_key: wrote %s (mode 600), key id %s" % (path, b21r_opauth.key_id(key).hex()))
        else:
            key = b21r_opauth.load_key(path)
            print("%s  %s" % (b21r_opauth.key_id(key).hex(), path))
    except (b21r_opauth.KeyFileError, OSError) as exc:
        sys.exit("b21r_key: %s" % exc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
