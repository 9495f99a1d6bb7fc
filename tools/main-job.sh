#!/usr/bin/env bash
# SPDX-License-Identifier: MIT
# tools/main-job.sh — the emulated B21r learns the corridor task (README, first command).
#
# 1. configures and builds the release preset (only the programs this job needs);
# 2. evaluates the reference controllers from the 10 evaluation poses (the "optimal" hand-tuned
#    one, the example policy at its nominal gain and at the gains 0.5, 1, 1.5, 2 its runs draw
#    from), each against its own emulator;
# 3. runs the two-phase learning with the paper's settings (30 example runs, 35 learned runs,
#    an evaluation block of 10 fixed poses every 5 training runs, alpha 0.2, gamma 0.99) against
#    the ODE emulator in lockstep over pseudo-terminals, printing progress as it goes;
# 4. writes the learning curve (PNG), a summary (text and JSON: each of the paper's claims with
#    yes/no and its numbers, paired over the poses, and who drove every run), the LCM logs, the
#    checkpoint and an overhead picture of every run into the output folder it names at the end;
# 5. measures what phase one saved: random exploration without examples (kinematic model, this
#    task and seed) until the first reward, against the session's training time (in the summary);
# 6. draws what was learned (policy_map_corridor.png: value and policy over a slice of the state
#    space beside the teacher and the optimal controller).
# The controllers publish on LCM on this host only (udpm with ttl=0), so the run can be watched
# with lcm-spy (tools/b21r-lcm-spy) or recorded with lcm-logger while it learns; without a
# multicast route the job says so and runs with LCM off.
# Environment: B21R_OUT (output folder, default build/main-job/<time>), B21R_SEED (default 1),
# B21R_BASE (rflex | canopen, default rflex), B21R_JOBS (build parallelism, default 2),
# B21R_LCM_URL (default udpm://239.255.76.67:7667?ttl=0; "none" = LCM off),
# B21R_REALTIME_FACTOR (lockstep pace cap, default 0 = as fast as possible; e.g. 20 lets
# lcm-logger over UDP keep up).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
say() { printf 'main-job: %s\n' "$*"; }
start=$(date +%s)

python="$repo/build/venv/bin/python3"
if [[ ! -x "$python" ]]; then
  say "error: no Python environment at build/venv; run tools/setup.sh first"
  exit 2
fi
preset=host-release
build="$repo/build/$preset"
jobs="${B21R_JOBS:-2}"
seed="${B21R_SEED:-1}"
base="${B21R_BASE:-rflex}"
out="${B21R_OUT:-$repo/build/main-job/$(date +%Y%m%d-%H%M%S)}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"

say "configuring and building the $preset preset (b21r-controller, b21r-sim, LCM types, the Python binding)"
if [[ ! -f "$build/build.ninja" ]]; then
  cmake --preset "$preset" >"$out/build.log" 2>&1 || { tail -30 "$out/build.log"; exit 1; }
fi
# b21r_learn_core: the picture of what was learned (step 6) reads the checkpoint through b21r_learn.
cmake --build --preset "$preset" -j "$jobs" --target b21r-controller b21r_sim_app b21r_msgs_python b21r_experiment \
  b21r_learn_core \
  >>"$out/build.log" 2>&1 || { tail -40 "$out/build.log"; say "error: build failed (log: $out/build.log)"; exit 1; }
controller="$build/bin/b21r-controller"
sim="$build/bin/b21r-sim"
world="$repo/sim/worlds/corridor10.world"
export PYTHONPATH="$build/python:$repo/tools${PYTHONPATH:+:$PYTHONPATH}"

sim_pid=""
cleanup() {
  if [[ -n "$sim_pid" ]]; then
    kill "$sim_pid" 2>/dev/null || true
    wait "$sim_pid" 2>/dev/null || true
  fi
}
trap cleanup EXIT

# start_sim NAME [b21r-sim args...]: starts an emulator and waits for its endpoints file.
start_sim() {
  local name="$1"
  shift
  rm -f "$out/$name.endpoints" "$out/$name.control"
  "$sim" --world "$world" --lockstep --base "$base" --seed "$seed" --control "$out/$name.control" \
    --endpoints "$out/$name.endpoints" "$@" >"$out/$name.sim.log" 2>&1 &
  sim_pid=$!
  for _ in $(seq 100); do
    [[ -s "$out/$name.endpoints" ]] && return 0
    kill -0 "$sim_pid" 2>/dev/null || break
    sleep 0.1
  done
  say "error: the emulator did not start (log: $out/$name.sim.log)"
  cat "$out/$name.sim.log" >&2
  exit 1
}

stop_sim() {
  kill "$sim_pid" 2>/dev/null || true
  wait "$sim_pid" 2>/dev/null || true
  sim_pid=""
}

lcm_url="${B21R_LCM_URL:-udpm://239.255.76.67:7667?ttl=0}"
if [[ "$lcm_url" != none ]] && ! "$python" -c 'import sys, lcm; lcm.LCM(sys.argv[1])' "$lcm_url" 2>/dev/null; then
  say "note: LCM cannot open $lcm_url (no multicast route? e.g. ip route add 224.0.0.0/4 dev lo);"
  say "      running with LCM off (the --log files still record everything)"
  lcm_url=none
fi
[[ "$lcm_url" != none ]] && say "live: lcm-spy or lcm-logger on $lcm_url (LCM_DEFAULT_URL='$lcm_url')"
common=(--set lockstep=true --set "lcm_url=$lcm_url" --set "seed=$seed"
        --set "lockstep_realtime_factor=${B21R_REALTIME_FACTOR:-0}")

# reference NAME POLICY [--set ...]: one evaluation block of a reference policy, own emulator.
reference() {
  local name="$1" policy="$2"
  shift 2
  start_sim "$name"
  "$controller" --endpoints "$out/$name.endpoints" "${common[@]}" --set mode=evaluate \
    --set "evaluate_policy=$policy" "$@" --log "$out/$name.lcmlog" --set progress=true \
    >"$out/$name.progress.txt" 2>"$out/$name.controller.log" ||
    { cat "$out/$name.controller.log" >&2; say "error: reference evaluation $name failed"; exit 1; }
  grep EVAL "$out/$name.progress.txt" | sed "s/^/main-job:   /"
  stop_sim
}

say "reference: the optimal controller from the 10 evaluation poses"
# The yardstick decides every tick, whatever decision_ticks the learner and its teachers use.
reference optimal optimal --set decision_ticks=1
say "reference: the example policy at its nominal gain (the middle of its training range)"
reference example example
# The examples' gains are drawn from [0.5, 2] per run: their best gain is the fair bar to beat.
gain_args=()
for gain in 0.5 1.0 1.5 2.0; do
  say "reference: the example policy at gain $gain"
  reference "example-gain-$gain" example --set "evaluate_example_gain=$gain"
  gain_args+=(--example-gain "$gain=$out/example-gain-$gain.lcmlog")
done

say "learning: 30 example runs, then 35 runs driven by the learned policy (progress below)"
start_sim learning --trace-svg "$out/trajectories.svg"
set +e
"$controller" --endpoints "$out/learning.endpoints" "${common[@]}" --set progress=true \
  --checkpoint "$out/hedger.ckpt" --log "$out/learning.lcmlog" --experience-log "$out/experiences.lcmlog" \
  2>"$out/learning.controller.log" | tee "$out/learning.progress.txt"
status=${PIPESTATUS[0]}
set -e
stop_sim
if [[ "$status" -ne 0 ]]; then
  cat "$out/learning.controller.log" >&2
  say "error: the controller exited with status $status"
  exit 1
fi

say "writing the learning curve and the summary"
"$python" "$repo/tools/b21r_learning_report.py" --log "$out/learning.lcmlog" \
  --optimal "$out/optimal.lcmlog" --example "$out/example.lcmlog" "${gain_args[@]}" --out "$out" \
  --title "Corridor following, emulated B21r ($base base, seed $seed)" >/dev/null

# What phase one saved this session, measured: random exploration without examples on the kinematic
# model (this task and seed, the product's assumptions: tools/experiments/explore_corridor_product.conf
# with the base's acceleration limits) until the first reward, against this session's training time;
# added to summary.txt and summary.json ("without_examples"). About a second.
say "without examples: random exploration to the first reward (kinematic model, this task and seed)"
"$build/bin/b21r-experiment" --config "$repo/tools/experiments/explore_corridor_product.conf" --seed "$seed" \
  --set experiment.explore_model=kinematic --set experiment.explore_accel_limits=true \
  --set experiment.explore_runs=200 --out "$out/without_examples.json" 2>"$out/without_examples.log" ||
  { cat "$out/without_examples.log" >&2; say "error: the random-exploration measurement failed"; exit 1; }
"$python" "$repo/tools/b21r_explore_saving.py" --explore "$out/without_examples.json" --summary-dir "$out" >/dev/null

cat "$out/summary.txt"

# Pictures of what was learned (a step of its own): the learned value and policy over a slice of
# the state space beside the teacher's and the optimal controller's commands, HEDGER's unknown
# region hatched (tools/b21r_policy_map.py; docs/tools.md).
say "drawing what was learned (policy_map_corridor.png)"
"$python" "$repo/tools/b21r_policy_map.py" --checkpoint "$out/hedger.ckpt" --out "$out" \
  --title "What was learned: corridor, emulated B21r ($base base, seed $seed)" | sed "s/^/main-job:   /"
say "finished in $(( $(date +%s) - start )) s"
say "output folder: $out"
say "  learning_curve.png  summary.txt  summary.json  trajectories.svg  policy_map_corridor.png  learning.lcmlog  hedger.ckpt"
