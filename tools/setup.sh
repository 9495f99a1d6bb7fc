#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# tools/setup.sh — installs everything the project needs on Debian 12, idempotently:
#   1. the Debian packages in tools/debian-packages.txt that are not installed yet
#      (apt-get update first; nothing at all when every package is present);
#   2. a Python virtual environment at build/venv with tools/requirements.txt (pinned), redone
#      only when the requirements file changes, with the project's own packages on its path
#      (tools/python, and build/host-release/python once built).
# Needs root (or sudo) only when a Debian package is missing. Safe to run any number of times.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
packages_file="$repo/tools/debian-packages.txt"
requirements="$repo/tools/requirements.txt"
venv="$repo/build/venv"

say() { printf 'setup: %s\n' "$*"; }

mapfile -t packages < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$packages_file" | grep -v '^$')
missing=()
for pkg in "${packages[@]}"; do
  status="$(dpkg-query -W -f='${db:Status-Status}' "$pkg" 2>/dev/null || true)"
  [[ "$status" == "installed" ]] || missing+=("$pkg")
done

if ((${#missing[@]})); then
  say "installing ${#missing[@]} Debian package(s): ${missing[*]}"
  if [[ "$(id -u)" -eq 0 ]]; then
    sudo=()
  elif command -v sudo >/dev/null; then
    sudo=(sudo)
  else
    say "error: packages are missing and this is not root (and there is no sudo)."
    say "fix: run as root: apt-get update && apt-get install -y ${missing[*]}"
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo[@]}" apt-get update -qq
  "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  say "all ${#packages[@]} Debian packages present"
fi

# Debian's interpreter, so the venv matches the machine the product targets.
python=/usr/bin/python3
[[ -x "$python" ]] || python="$(command -v python3)"
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$requirements" | cut -d' ' -f1)"
if [[ ! -x "$venv/bin/python3" || ! -f "$stamp" || "$(cat "$stamp")" != "$want" ]]; then
  say "creating Python environment $venv"
  rm -rf "$venv"
  mkdir -p "$(dirname "$venv")"
  "$python" -m venv "$venv"
  "$venv/bin/python3" -m pip install --quiet --disable-pip-version-check --upgrade pip
  "$venv/bin/python3" -m pip install --quiet --disable-pip-version-check -r "$requirements"
  echo "$want" >"$stamp"
else
  say "Python environment up to date ($venv)"
fi
# The project's own Python packages in that environment: b21r_learn (tools/python, its compiled
# part in the host-release build) and the generated LCM types, importable once built.
site="$("$venv/bin/python3" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
printf '%s\n' "$repo/tools/python" "$repo/build/host-release/python" >"$site/b21r-project.pth"
say "done"
