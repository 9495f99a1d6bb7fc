#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Long fuzzing campaign: runs fuzz targets of the fuzz preset one after the other (never two at
# once), each in one process for a fixed number of executions, on a corpus that grows in
# build/fuzz/campaign/<target> (seeded from test/fuzz/corpus/<target>). Prints one line per
# target: executions, wall time, result; a finding stops that target and leaves the input in
# build/fuzz/campaign/<target>-crash-* (or -leak-, -timeout-, -oom-).
#   usage: test/fuzz/campaign.sh [-n EXECUTIONS] [TARGET...]     (default: 10000000, every target)
# Build first: cmake --preset fuzz && cmake --build --preset fuzz --target b21r_fuzzers
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
runs=10000000
if [[ "${1:-}" == "-n" ]]; then
  runs="$2"
  shift 2
fi
bin=${B21R_FUZZ_BIN:-build/fuzz/test/fuzz}  # or a copy, to keep building meanwhile
out=build/fuzz/campaign
mkdir -p "$out"
targets=("$@")
if ((${#targets[@]} == 0)); then
  mapfile -t targets < <(ls test/fuzz/corpus)
fi
printf '%-15s %12s %10s  %s\n' target executions wall_s result
for t in "${targets[@]}"; do
  mkdir -p "$out/$t"
  start=$(date +%s)
  set +e
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1 "$bin/fuzz_$t" -runs="$runs" -seed=1 -timeout=10 \
    -rss_limit_mb=2048 -malloc_limit_mb=64 -print_final_stats=1 -artifact_prefix="$out/$t-" \
    "$out/$t" "test/fuzz/corpus/$t" >"$out/$t.log" 2>&1
  rc=$?
  set -e
  wall=$(($(date +%s) - start))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$out/$t.log" | tail -1)
  result=$([[ $rc -eq 0 ]] && echo "no finding" || echo "FINDING (exit $rc): see $out/$t.log")
  printf '%-15s %12s %10s  %s\n' "$t" "${execs:-?}" "$wall" "$result"
done
