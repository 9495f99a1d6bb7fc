#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Long fuzzing campaign: runs fuzz targets of the fuzz preset one after the other (never two at
# once) until each has had a fixed number of executions, on a corpus that grows in
# build/fuzz/campaign/<target> (seeded from test/fuzz/corpus/<target>). The executions come in
# chunks of one process each (-c; libFuzzer seed = the chunk's number), and every finished chunk
# is appended to build/fuzz/campaign/<target>.ledger (date, source commit, executions, seconds,
# result), so a campaign stopped part-way resumes where its last chunk ended: run the same
# command again. Delete a target's ledger to start its count over. Prints one line per target:
# executions (all chunks), wall time, chunks, result. A finding stops that target and leaves the
# input in build/fuzz/campaign/<target>-crash-* (or -leak-, -timeout-, -oom-).
#   usage: test/fuzz/campaign.sh [-n EXECUTIONS] [-c CHUNK] [TARGET...]
#          (default: 10000000 executions in one chunk, every target)
# Build first: cmake --preset fuzz && cmake --build --preset fuzz --target b21r_fuzzers
# In the background on a shared machine: `setsid nice -n 19 test/fuzz/campaign.sh ...`. Run so, as
# a session of its own, the script also lowers its session's scheduler autogroup to that nice
# value: with autogroups (Debian's default) nice alone does not yield to other sessions.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
runs=10000000
chunk=0
while [[ "${1:-}" == -n || "${1:-}" == -c ]]; do
  [[ "$1" == -n ]] && runs="$2" || chunk="$2"
  shift 2
done
((chunk > 0 && chunk <= runs)) || chunk=$runs
if (($(nice) > 0)) && [[ "$(ps -o sid= -p $$ | tr -d ' ')" == "$$" && -w /proc/self/autogroup ]]; then
  echo "$(nice)" >/proc/self/autogroup || true
fi
bin=${B21R_FUZZ_BIN:-build/fuzz/test/fuzz}  # or a copy, to keep building meanwhile
commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
out=build/fuzz/campaign
mkdir -p "$out"
targets=("$@")
if ((${#targets[@]} == 0)); then
  mapfile -t targets < <(ls test/fuzz/corpus)
fi
# ledger_totals LEDGER: "executions wall_s chunks" summed over its rows (date commit executions wall_s result)
ledger_totals() { awk '{e += $3; w += $4; n++} END {print e + 0, w + 0, n + 0}' "$1"; }
printf '%-15s %12s %10s %7s  %s\n' target executions wall_s chunks result
for t in "${targets[@]}"; do
  mkdir -p "$out/$t"
  ledger="$out/$t.ledger"
  touch "$ledger"
  result="no finding"
  while :; do
    read -r done_execs done_wall chunks < <(ledger_totals "$ledger")
    if grep -q FINDING "$ledger"; then
      result="FINDING earlier: see $ledger"
      break
    fi
    ((done_execs < runs)) || break
    n=$((runs - done_execs < chunk ? runs - done_execs : chunk))
    start=$(date +%s)
    set +e
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1 "$bin/fuzz_$t" -runs="$n" -seed=$((chunks + 1)) \
      -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=64 -print_final_stats=1 -artifact_prefix="$out/$t-" \
      "$out/$t" "test/fuzz/corpus/$t" >"$out/$t.log" 2>&1
    rc=$?
    set -e
    wall=$(($(date +%s) - start))
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$out/$t.log" | tail -1)
    # libFuzzer's -timeout is wall time: a process starved by other work (nice 19 beside a full
    # load) can pass it on any input. A timeout input that runs within the limit on its own is
    # such a case: the chunk counts as interrupted, its executions as done, the input is kept as
    # <target>-starved-*, and the next chunk continues.
    timeout_input=$(find "$out" -maxdepth 1 -name "$t-timeout-*" -newer "$ledger" -print -quit)
    if ((rc != 0)) && [[ -n "$timeout_input" ]] &&
      ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1 "$bin/fuzz_$t" -timeout=10 -runs=1 \
        "$timeout_input" >"$out/$t.rerun.log" 2>&1; then
      mv "$timeout_input" "$out/$t-starved-${timeout_input##*-}"
      rc=0
      result_word=interrupted-by-starvation
    else
      result_word=no-finding
    fi
    if ((rc == 0)); then
      echo "$(date -u +%FT%TZ) $commit ${execs:-0} $wall $result_word" >>"$ledger"
    else
      echo "$(date -u +%FT%TZ) $commit ${execs:-0} $wall FINDING(exit-$rc)" >>"$ledger"
      result="FINDING (exit $rc): see $out/$t.log"
      break
    fi
  done
  read -r done_execs done_wall chunks < <(ledger_totals "$ledger")
  starved=$(grep -c interrupted-by-starvation "$ledger" || true)
  ((starved == 0)) || result="$result ($starved chunk(s) cut short by a starvation timeout whose input reran fine)"
  printf '%-15s %12s %10s %7s  %s\n' "$t" "$done_execs" "$done_wall" "$chunks" "$result"
done
