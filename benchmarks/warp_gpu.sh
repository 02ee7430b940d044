#!/usr/bin/env bash
# MuJoCo Warp beside MJX-JAX on one GPU, every benchmark in one run of about 9 minutes:
#
#   bash benchmarks/warp_gpu.sh "$OUT"
#
# Stages, most important first, each under its own time limit and all under one deadline
# (WARP_GPU_BUDGET_S, default 550 s), so the run ends before a 10-minute limit whatever
# happens; a stage that fails or runs out of time is reported and the next one runs:
#   1. launch    `python -m mjzoo train ppo cartpole_balance --impl warp`, one update,
#                twice with the JAX persistent compilation cache (and Warp's kernel cache):
#                process start to the first metrics.jsonl record, cold then warm.
#   2. humanoid  locomotion.py: PPO humanoid_walk on Warp to the stated return 6000 (time
#                with compile, steps/s, fraction of raw stepping; the JAX figures are in
#                results/locomotion/locomotion_gpu_humanoid_walk.json: 206 s, 355k steps/s).
#                LOCOMOTION_IMPLS="warp jax" adds JAX, if the deadline allows (~4 min).
#   3. planner   planner_latency.py: MPPI on the humanoid, 1024 samples over 0.5 s, both.
#   4. stepping  task_overhead.py: raw stepping and the task layer, the humanoid at 4096
#                envs, both (stage 5 has the cart-pole's raw stepping at 2048).
#   5. ppo       ppo_vs_brax.py: cartpole_balance, mjzoo PPO and Brax PPO, 4 Brax epochs
#                (3.9M steps), Warp then JAX (each row is saved as soon as it is done).
# The XLA cache is on only for stage 1: the other stages' compile times are cold, as in
# the committed JAX results. Warp's kernel cache (~/.cache/warp) stays warm after stage 1.
# Copies the JSON results and this log into OUT (at most 8 files) after every stage.
set -u
OUT=${1:?usage: bash benchmarks/warp_gpu.sh OUT_DIR}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
cd "$(dirname "$0")/.."
[ -f .venv/bin/activate ] && . .venv/bin/activate
PY=${PYTHON:-python}
RES=$(mktemp -d /tmp/warp_gpu.XXXXXX)
LOG=$OUT/warp_gpu_log.txt
# Warp prints a line per kernel module it loads: left out of the log.
exec > >(grep --line-buffered -v "^Module .* load on device" | tee -a "$LOG") 2>&1
DEADLINE=$((SECONDS + ${WARP_GPU_BUDGET_S:-550}))

# The seconds a stage may run: its own limit, or what is left before the deadline.
allowed() { local left=$((DEADLINE - SECONDS)); echo $(($1 < left ? $1 : left)); }

# Runs a stage (name, limit in seconds, command...) under its limit (a shell function
# keeps its own limits); skips it when fewer than 20 s are left.
stage() {
  local name=$1 limit
  limit=$(allowed "$2")
  shift 2
  if ((limit < 20)); then echo "== $name: skipped, ${limit} s left"; return; fi
  echo "== $name (limit ${limit} s, $((DEADLINE - SECONDS)) s left): $*"
  local start=$SECONDS
  if [ "$(type -t "$1")" = function ]; then "$@"; else timeout -k 5 "$limit" "$@"; fi
  local rc=$?
  echo "== $name: exit $rc after $((SECONDS - start)) s$( ((rc == 124 || rc == 137)) && echo ' (out of time)')"
  collect
}

# Copies the results so far into OUT (a later stage that overruns leaves these).
collect() {
  local f
  for f in "$RES"/launch_gpu.json "$RES"/locomotion/locomotion_*.json "$RES"/locomotion/*/metrics.jsonl \
    "$RES"/planner_latency_*.json "$RES"/task_overhead_*.json "$RES"/ppo_vs_brax_*.json; do
    [ -f "$f" ] || continue
    case $f in */metrics.jsonl) cp "$f" "$OUT/$(basename "$(dirname "$f")")_metrics.jsonl" ;; *) cp "$f" "$OUT/" ;; esac
  done
}

# Seconds from launching `mjzoo train` (one PPO update of cartpole_balance on Warp) to
# its first metrics record, or "null"; $1 names the run, $2 is its time limit.
launch() {
  local dir=$RES/launch_$1 t0 t1 pid
  t0=$(date +%s.%N)
  JAX_COMPILATION_CACHE_DIR=$RES/jax_cache JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS=0 \
    JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES=-1 timeout -k 5 "$(allowed "$2")" \
    "$PY" -m mjzoo train ppo cartpole_balance --impl warp --total-steps 8192 --updates-per-chunk 1 \
    --eval-envs 16 --no-video --out "$dir" >"$RES/launch_$1.log" 2>&1 &
  pid=$!
  while kill -0 "$pid" 2>/dev/null && ! [ -s "$dir/metrics.jsonl" ]; do sleep 0.05; done
  t1=$(date +%s.%N)
  wait "$pid"
  if [ -s "$dir/metrics.jsonl" ]; then awk "BEGIN { printf \"%.2f\", $t1 - $t0 }"; else echo null; fi
}

launch_stage() {
  local cold warm
  cold=$(launch cold 150)  # a fresh machine compiles Warp's CUDA kernels here
  warm=$(launch warm 60)
  tail -n 3 "$RES/launch_warm.log"
  echo "launch to first PPO update (cartpole_balance, Warp): cold caches ${cold} s, warm ${warm} s (goal < 15 s)"
  printf '{"env": "cartpole_balance", "impl": "warp", "cold_s": %s, "warm_s": %s, "goal_s": 15}\n' \
    "$cold" "$warm" >"$RES/launch_gpu.json"
}

echo "warp_gpu.sh: $(date -u), commit $(git rev-parse --short HEAD 2>/dev/null), results in $RES"
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader 2>/dev/null
stage launch 200 launch_stage
# 36M steps: the JAX run reached 6000 at 32.8M.
stage humanoid 240 "$PY" benchmarks/locomotion.py --tasks humanoid_walk --steps 36000000 --no-final-eval \
  --no-video --impl ${LOCOMOTION_IMPLS:-warp} --out "$RES/locomotion"
stage planner 80 "$PY" benchmarks/planner_latency.py --envs humanoid_walk --samples 1024 --horizons 10 \
  --no-extras --repeats 10 --physics dt=0.025 ctrl_dt=0.05 iterations=1 ls_iterations=2 --impl warp jax \
  --tag humanoid_impls --out "$RES"
stage stepping 70 "$PY" benchmarks/task_overhead.py --envs humanoid_walk --batch 4096 --steps 100 --repeats 3 \
  --impl warp jax --tag impls --out "$RES"
stage ppo 300 "$PY" benchmarks/ppo_vs_brax.py --envs cartpole_balance --steps 3932160 --impl warp jax \
  --tag impls --out "$RES"

echo "== summary"
"$PY" - "$OUT" <<'EOF'
import json, sys
from pathlib import Path

out = Path(sys.argv[1])
def load(pattern):
    return [json.loads(p.read_text()) for p in sorted(out.glob(pattern))]
fmt = lambda x, spec=".1f": "-" if x is None else format(x, spec)
for d in load("launch_gpu.json"):
    print(f"launch to first update (warp, cartpole): cold {fmt(d['cold_s'])} s, warm {fmt(d['warm_s'])} s  [goal < 15 s]")
for d in load("locomotion_*.json"):
    for r in d["rows"]:
        print(f"{r['task']} ({r['impl']}): return {r['threshold']:.0f} at {fmt(r['time_to_threshold_s'])} s with compile "
              f"[goal < 90 s], {r['steps_per_s']:,.0f} steps/s = {r['fraction_of_raw']:.2f} of raw "
              f"{r['raw_steps_per_s']:,.0f} [goal >= 0.6], first update at {r['first_update_s']:.1f} s")
for d in load("planner_latency_*.json"):
    for r in d["rows"]:
        print(f"planner {r['env']} ({r['impl']}): {r['samples']} samples over {r['horizon_s']:.2f} s: "
              f"{r['plan_hz']:.0f} Hz [goal >= 150], bare rollouts {r['bare_ms']:.2f} ms")
for d in load("task_overhead_*.json"):
    for r in d["rows"]:
        print(f"stepping {r['env']} ({r['impl']}) x{r['batch']}: raw {r['raw_steps_per_s']:,.0f}, "
              f"transition {r['transition_steps_per_s']:,.0f}, auto-reset {r['auto_reset_steps_per_s']:,.0f} steps/s")
for d in load("ppo_vs_brax_*.json"):
    for r in d["rows"]:
        for name in ("mjzoo", "brax"):
            res = r[name]
            if "error" in res:
                print(f"ppo {r['env']} ({r['impl']}) {name}: did not run: {res['error'][:300]}")
            else:
                print(f"ppo {r['env']} ({r['impl']}) {name}: {res['steps_per_s']:,.0f} steps/s = "
                      f"{r[f'{name}_fraction_of_raw']:.2f} of raw, to {r['threshold']:.0f} in "
                      f"{fmt(r[f'{name}_time_to_threshold_s'])} s, final {res['final_return']:.1f}")
EOF
echo "files in $OUT: $(ls "$OUT" | tr '\n' ' ')"
sleep 1  # lets tee write the last lines
