#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# tools/setup.sh — installs everything the project needs on Debian 12, idempotently:
#   1. the Debian packages in tools/debian-packages.txt that are not installed yet
#      (apt-get update first; nothing at all when every package is present);
#   2. a Python virtual environment at build/venv with tools/requirements.txt (pinned), redone
#      only when the requirements file changes, with the project's own packages on its path
#      (tools/python, and build/host-release/python once built).
# With --arm64, also what the robot-arm64 cross build needs (docs/robot.md):
#   3. the build machine's packages of tools/debian-packages-arm64.txt (cross compilers,
#      qemu-user, mmdebstrap);
#   4. build/arm64-sysroot: Debian 12's arm64 packages of tools/arm64-sysroot-packages.txt with
#      their dependencies, unpacked from the machine's Debian mirror (remade when the list changes);
#   5. build/arm64-python/lcm: the LCM Python binding for arm64 (the pinned wheel of
#      tools/requirements.txt), which the arm64 Debian package ships.
# Needs root (or sudo) only when a Debian package is missing or for the sysroot. Safe to run any
# number of times.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
packages_file="$repo/tools/debian-packages.txt"
requirements="$repo/tools/requirements.txt"
venv="$repo/build/venv"

say() { printf 'setup: %s\n' "$*"; }

arm64=false
for arg in "$@"; do
  case "$arg" in
    --arm64) arm64=true ;;
    -h | --help)
      sed -n '3,/^set -euo/p' "${BASH_SOURCE[0]}" | sed -e '$d' -e 's/^# \{0,1\}//'
      exit 0 ;;
    *) say "error: unknown option '$arg' (options: --arm64, --help)"; exit 2 ;;
  esac
done

as_root() {
  if [[ "$(id -u)" -eq 0 ]]; then
    "$@"
  elif command -v sudo >/dev/null; then
    sudo "$@"
  else
    say "error: this step needs root (and there is no sudo): $*"
    say "fix: run tools/setup.sh $([[ $arm64 == true ]] && echo --arm64) as root"
    exit 1
  fi
}

# Installs the packages of a list file (one name per line, # comments) that are missing.
install_missing() {
  local file="$1" pkg status
  local -a packages missing=()
  mapfile -t packages < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$file" | grep -v '^$')
  for pkg in "${packages[@]}"; do
    status="$(dpkg-query -W -f='${db:Status-Status}' "$pkg" 2>/dev/null || true)"
    [[ "$status" == "installed" ]] || missing+=("$pkg")
  done
  if ((${#missing[@]})); then
    say "installing ${#missing[@]} Debian package(s): ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    as_root apt-get update -qq
    as_root apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    say "all ${#packages[@]} Debian packages of $(basename "$file") present"
  fi
}

install_missing "$packages_file"
if [[ $arm64 == true ]]; then
  install_missing "$repo/tools/debian-packages-arm64.txt"
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

# The arm64 sysroot, from the same Debian 12 mirror and suites this machine's apt uses.
arm64_sysroot() {
  local list="$repo/tools/arm64-sysroot-packages.txt" root="$repo/build/arm64-sysroot"
  local want have include
  want="$(sha256sum "$list" | cut -d' ' -f1)"
  have="$(cat "$root/.packages.sha256" 2>/dev/null || true)"
  if [[ -f "$root/usr/include/lcm/lcm.h" && "$have" == "$want" ]]; then
    say "arm64 sysroot up to date ($root)"
    return
  fi
  include="$(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$list" | grep -v '^$' | paste -sd, -)"
  local -a sources
  mapfile -t sources < <(apt-cache policy | awk '$3 ~ /^bookworm(-updates|-security)?\/main$/ && $4 == "amd64" {
      split($3, s, "/"); print "deb " $2 " " s[1] " main" }' | sort -u)
  if ((${#sources[@]} == 0)); then
    say "error: no Debian 12 (bookworm) main source in this machine's apt configuration"
    exit 1
  fi
  say "making the arm64 sysroot $root from ${sources[*]}"
  as_root rm -rf "$root.new"
  if ! as_root mmdebstrap --quiet --variant=extract --arch=arm64 --mode=root \
    --hook-dir=/usr/share/mmdebstrap/hooks/merged-usr --include="$include" bookworm "$root.new" "${sources[@]}" \
    >"$repo/build/arm64-sysroot.log" 2>&1; then
    cat "$repo/build/arm64-sysroot.log"
    say "error: mmdebstrap failed (log above: build/arm64-sysroot.log)"
    exit 1
  fi
  # No device nodes: qemu-aarch64 -L would take the sysroot's /dev/ptmx for the host's.
  as_root rm -rf "$root.new/dev"
  as_root rm -rf "$root"
  as_root mv "$root.new" "$root"
  echo "$want" | as_root tee "$root/.packages.sha256" >/dev/null
}

# The LCM Python binding for arm64: the wheel of the version tools/requirements.txt pins.
arm64_python_lcm() {
  local out="$repo/build/arm64-python" version wheel
  version="$(sed -n 's/^lcm==\([^[:space:]#]*\).*/\1/p' "$requirements")"
  if [[ -f "$out/.version" && "$(cat "$out/.version")" == "$version" ]]; then
    say "arm64 LCM Python binding $version present ($out)"
    return
  fi
  say "fetching the arm64 LCM Python binding lcm==$version"
  rm -rf "$out" && mkdir -p "$out/wheel"
  "$venv/bin/python3" -m pip download --quiet --disable-pip-version-check --no-deps --only-binary=:all: \
    --platform manylinux_2_28_aarch64 --python-version 3.11 --implementation cp --abi cp311 \
    -d "$out/wheel" "lcm==$version"
  wheel="$(ls "$out"/wheel/lcm-*.whl)"
  "$venv/bin/python3" -m zipfile -e "$wheel" "$out"
  echo "$version" >"$out/.version"
}

if [[ $arm64 == true ]]; then
  arm64_sysroot
  arm64_python_lcm
fi
say "done"
