# SPDX-License-Identifier: MIT
"""b21r_bootstrap: lets every Python tool of the project run as written from a plain shell.

A tool starts with

    #!/usr/bin/env python3
    import b21r_bootstrap
    b21r_bootstrap.ensure()            # before importing lcm, numpy, the generated types, ...

and then:
1. when it was started by an interpreter other than the project's venv (build/venv, made by
   tools/setup.sh), it re-executes itself with the venv's interpreter (same arguments, same
   environment), or stops with a message naming tools/setup.sh when there is no venv;
2. it puts the generated LCM types (`import b21r`) and the project's own Python packages on
   sys.path: the build named by B21R_BUILD_DIR, else the first of build/host-release,
   build/host-debug that holds them; with `need_types=True` (the default) it stops with the
   build command when none does. The packages are tools/ (the tools' modules), tools/python
   (b21r_learn) and the build's python/ folder (the generated types, b21r_learn's compiled part);
3. when that build's compiled Python extension carries AddressSanitizer (host-debug), it
   re-executes once more with the sanitizer runtime (and libstdc++, for ASan's exception
   interceptor) preloaded, leak detection off (the interpreter keeps memory until exit): such an
   extension does not load otherwise.

Installed by the Debian package (docs/robot.md), the tools sit beside the generated types and
the LCM binding in one folder (/usr/lib/b21r-controller/python): ensure() then does nothing, and
Debian's python3 runs them.

Only the standard library is used here, so the module works under any Python 3.
"""
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
VENV = REPO / "build" / "venv"
VENV_PYTHON = VENV / "bin" / "python3"
# Searched in this order for the generated Python types (build/<preset>/python/b21r).
PRESETS = ("host-release", "host-debug", "host-coverage")
BUILD_HINT = "cmake --preset host-release && cmake --build --preset host-release"

_GUARD = "B21R_BOOTSTRAPPED"
_PRELOAD_GUARD = "B21R_SANITIZER_PRELOADED"
# Written by tools/python/CMakeLists.txt into a sanitized build: the runtime to preload.
_PRELOAD_MARKER = "python/b21r_learn/sanitizer-preload.txt"


def _tool_name():
    return Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "b21r tool"


def _in_venv():
    try:
        return Path(sys.prefix).resolve() == VENV.resolve()
    except OSError:
        return False


def build_dirs():
    """Candidate build folders, most preferred first (B21R_BUILD_DIR, then the presets)."""
    dirs = []
    env = os.environ.get("B21R_BUILD_DIR")
    if env:
        dirs.append(Path(env).resolve())
    dirs.extend(REPO / "build" / p for p in PRESETS)
    return dirs


def find_build(marker="python/b21r/__init__.py"):
    """The first candidate build folder that holds `marker`, or None."""
    for d in build_dirs():
        if (d / marker).is_file():
            return d
    return None


def installed():
    """True when this module is the Debian package's (the generated types beside it)."""
    return (HERE / "b21r" / "__init__.py").is_file()


def ensure(need_types=True):
    """Re-executes under the project's venv if needed, then makes the generated types importable.
    Returns the build folder used (a Path), or None when need_types is False and none exists;
    installed by the package, its own folder."""
    if installed():
        return HERE
    if not _in_venv():
        if os.environ.get(_GUARD) == "1" or not VENV_PYTHON.exists():
            sys.exit(
                "%s: the project's Python environment is missing (%s); run tools/setup.sh first"
                % (_tool_name(), VENV)
            )
        os.environ[_GUARD] = "1"
        script = os.path.abspath(sys.argv[0])
        os.execv(str(VENV_PYTHON), [str(VENV_PYTHON), script] + sys.argv[1:])
    build = find_build()
    if build is None:
        if need_types:
            sys.exit(
                "%s: the generated LCM types are not built (looked in %s); build them with: %s"
                % (_tool_name(), ", ".join(str(d / "python") for d in build_dirs()), BUILD_HINT)
            )
        return None
    _preload_sanitizer(build)
    for p in (str(build / "python"), str(REPO / "tools" / "python"), str(REPO / "tools")):
        if p not in sys.path:
            sys.path.insert(0, p)
    return build


def _preload_sanitizer(build):
    """Re-executes with the sanitizer runtime preloaded when the build's extension needs it."""
    marker = build / _PRELOAD_MARKER
    if not marker.is_file():
        return
    runtime = [p for p in marker.read_text().strip().split(":") if p]
    preloaded = [p for p in os.environ.get("LD_PRELOAD", "").split(":") if p]
    if not runtime or preloaded[: len(runtime)] == runtime:
        return
    if os.environ.get(_PRELOAD_GUARD) == "1":
        sys.exit("%s: cannot preload the sanitizer runtime %s (named in %s)" % (_tool_name(), runtime, marker))
    os.environ[_PRELOAD_GUARD] = "1"
    os.environ["LD_PRELOAD"] = ":".join(runtime + [p for p in preloaded if p not in runtime])
    os.environ.setdefault("ASAN_OPTIONS", "detect_leaks=0")
    script = os.path.abspath(sys.argv[0])
    os.execv(sys.executable, [sys.executable, script] + sys.argv[1:])


def find_program(name):
    """Path of a program the build makes (build/<preset>/bin/<name>), or None."""
    d = find_build(marker="bin/" + name)
    return d / "bin" / name if d is not None else None
