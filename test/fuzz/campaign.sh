#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# Long fuzzing campaign: runs fuzz targets of the fuzz preset one after the other until each has
# had a fixed number of executions, on a corpus that grows in build/fuzz/campaign/<target>
# (seeded from test/fuzz/corpus/<target>). The executions come in chunks of one process each
# (-c; libFuzzer seed = the chunk's number); -j runs that many chunks of a target at once, on the
# shared corpus (one per core: libFuzzer itself is single-threaded). Every finished chunk is
# appended to build/fuzz/campaign/<target>.ledger (date, source commit, executions, seconds,
# result), so a campaign stopped part-way resumes where its last chunks ended: run the same
# command again. Delete a target's ledger to start its count over. Prints one line per target:
# executions (all chunks), process seconds (summed over chunks), wall seconds of this invocation,
# chunks, result. A finding stops that target and leaves the input in
# build/fuzz/campaign/<target>-crash-* (or -leak-, -timeout-, -oom-).
#   usage: test/fuzz/campaign.sh [-n EXECUTIONS] [-c CHUNK] [-j JOBS] [TARGET...]
#          (default: 10000000 executions in one chunk, one job, every target)
# Build first: cmake --preset fuzz && cmake --build --preset fuzz --target b21r_fuzzers
# In the background on a shared machine: `setsid nice -n 19 test/fuzz/campaign.sh ...`. Run so, as
# a session of its own, the script also lowers its session's scheduler autogroup to that nice
# value: with autogroups (Debian's default) nice alone does not yield to other sessions.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
runs=10000000
chunk=0
jobs=1
while [[ "${1:-}" =~ ^-[ncj]$ ]]; do
  case "$1" in
    -n) runs="$2" ;;
    -c) chunk="$2" ;;
    -j) jobs="$2" ;;
  esac
  shift 2
done
((chunk > 0 && chunk <= runs)) || chunk=$runs
((jobs >= 1)) || jobs=1
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
# ledger_totals LEDGER: "executions process_s chunks" summed over its rows (date commit executions seconds result)
ledger_totals() { awk '{e += $3; w += $4; n++} END {print e + 0, w + 0, n + 0}' "$1"; }

# run_chunk TARGET EXECUTIONS SEED LOG: one libFuzzer process; appends its ledger row. Returns 0
# unless the chunk found something.
run_chunk() {
  local t=$1 n=$2 seed=$3 log=$4 start rc execs artifact result_word
  start=$(date +%s)
  set +e
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1 "$bin/fuzz_$t" -runs="$n" -seed="$seed" \
    -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=64 -print_final_stats=1 -artifact_prefix="$out/$t-" \
    "$out/$t" "test/fuzz/corpus/$t" >"$log" 2>&1
  rc=$?
  set -e
  local wall=$(($(date +%s) - start))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  # libFuzzer's -timeout is wall time: a process starved by other work (nice 19 beside a full
  # load) can pass it on any input. A timeout input that runs within the limit on its own is
  # such a case: the chunk counts as interrupted, its executions as done, the input is kept as
  # <target>-starved-*, and the next chunk continues.
  artifact=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$log" | tail -1)
  result_word=no-finding
  if ((rc != 0)) && [[ "$artifact" == "$out/$t-timeout-"* && -f "$artifact" ]] &&
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1 "$bin/fuzz_$t" -timeout=10 -runs=1 \
      "$artifact" >"$log.rerun" 2>&1; then
    mv "$artifact" "$out/$t-starved-${artifact##*-}"
    rc=0
    result_word=interrupted-by-starvation
  fi
  ((rc == 0)) || result_word="FINDING(exit-$rc)"
  # One short line per append: concurrent chunks never interleave within a row.
  echo "$(date -u +%FT%TZ) $commit ${execs:-0} $wall $result_word" >>"$ledger"
  ((rc == 0))
}

for t in "${targets[@]}"; do
  if [[ ! -x "$bin/fuzz_$t" ]]; then
    echo "campaign.sh: no $bin/fuzz_$t; build the fuzz preset first (see above) or name a target of test/fuzz/corpus" >&2
    exit 2
  fi
done
printf '%-15s %12s %10s %8s %7s  %s\n' target executions process_s wall_s chunks result
for t in "${targets[@]}"; do
  mkdir -p "$out/$t"
  ledger="$out/$t.ledger"
  touch "$ledger"
  result="no finding"
  started=$(date +%s)
  while :; do
    read -r done_execs _ chunks < <(ledger_totals "$ledger")
    if grep -q FINDING "$ledger"; then
      result="FINDING: see $ledger and $out/$t.log*"
      break
    fi
    ((done_execs < runs)) || break
    # A batch of up to $jobs chunks that together do not pass the target count.
    left=$((runs - done_execs))
    pids=()
    for ((i = 0; i < jobs && left > 0; ++i)); do
      n=$((left < chunk ? left : chunk))
      left=$((left - n))
      log="$out/$t.log"
      ((i == 0)) || log="$out/$t.log.$i"
      run_chunk "$t" "$n" $((chunks + 1 + i)) "$log" &
      pids+=($!)
    done
    for pid in "${pids[@]}"; do
      wait "$pid" || true  # a finding is in the ledger; the check above stops the target
    done
    if (($(ledger_totals "$ledger" | cut -d' ' -f1) == done_execs)) && ! grep -q FINDING "$ledger"; then
      result="NO PROGRESS: the last chunks ran no input; see $out/$t.log"
      break
    fi
  done
  read -r done_execs done_process chunks < <(ledger_totals "$ledger")
  starved=$(grep -c interrupted-by-starvation "$ledger" || true)
  ((starved == 0)) || result="$result ($starved chunk(s) cut short by a starvation timeout whose input reran fine)"
  printf '%-15s %12s %10s %8s %7s  %s\n' "$t" "$done_execs" "$done_process" $(($(date +%s) - started)) "$chunks" "$result"
done
