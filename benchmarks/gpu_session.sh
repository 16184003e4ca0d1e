#!/usr/bin/env bash
# The benchmarks on a GPU machine, in one command (see benchmarks/README.md, "On a GPU").
#
# Usage, from the repository root of a copy of the tree on the GPU machine, whose Python
# already holds jax with its CUDA plugin, equinox, optimistix, numpy, scipy and matplotlib:
#
#     JMSE_COMMIT=<sha> OUT=<folder> bash benchmarks/gpu_session.sh PHASE [PHASE ...]
#
# Phases (each with its own time limit, run in the order given):
#   env         the GPU, the driver and the versions
#   check       benchmarks/device_check.py: GPU against CPU, every bank case (float64)
#   sweep       benchmarks/sweep_bench.py, fast preset, float64, the 1875 designs at once
#   sweep32     the same in float32
#   sweepbs     the fast preset, float64, at batch sizes 64 and 256
#   sweepdef    the default (adaptive) preset, float64, 256 designs per vmap
#   sweepdefbs  the default preset, float64, 64 and 256 designs per vmap, one run each
#   sweepdef1   the default preset, float64, one design at a time (lax.map, no vmap)
#   sweepdefgrad  the default preset's gradient sweep, 256 designs per vmap, long limit
#   speed       benchmarks/accuracy_speed.py on the baselines, fast and default presets
# Results (JSON, markdown, PNG) are written to benchmarks/results/*gpu*, and copied with
# the log into $OUT/gpu_results.tgz after every phase, so a phase cut short keeps the rest.
set -u
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
export XLA_PYTHON_CLIENT_PREALLOCATE=false  # the sweep's driver and workers share the GPU
OUT=${OUT:-/tmp/jmse_gpu_out}
mkdir -p "$OUT"
LOG="$OUT/gpu_session.log"
PY=${PYTHON:-python3}

save() {
    tar czf "$OUT/gpu_results.tgz" benchmarks/results/*gpu* "$LOG" 2>/dev/null || true
}

phase() {  # phase NAME LIMIT_S COMMAND...
    local name=$1 limit=$2
    shift 2
    echo "=== $name ($(date -u +%H:%M:%S), limit ${limit} s): $*" | tee -a "$LOG"
    local start=$SECONDS
    timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
    echo "=== $name done in $((SECONDS - start)) s, exit ${PIPESTATUS[0]}" | tee -a "$LOG"
    save
}

SWEEP="$PY benchmarks/sweep_bench.py --devices 1 --repeats 3 --tag"

for name in "$@"; do
    case $name in
        env)
            phase env 60 bash -c "nvidia-smi --query-gpu=name,memory.total,driver_version \
                --format=csv; nproc; $PY -c 'import jax, equinox, optimistix, numpy, scipy; \
                print(jax.__version__, equinox.__version__, optimistix.__version__, \
                numpy.__version__, jax.devices())'" ;;
        check) phase check 240 $PY benchmarks/device_check.py --tag gpu ;;
        sweep) phase sweep 200 $SWEEP gpu_fast --preset fast --batch-size 1875 --timeout 90 ;;
        sweep32)
            phase sweep32 200 $SWEEP gpu_fast_float32 --preset fast --dtype float32 \
                --batch-size 1875 --timeout 90 ;;
        sweepbs)
            phase sweepbs64 150 $SWEEP gpu_fast_b64 --preset fast --batch-size 64 --timeout 70
            phase sweepbs256 150 $SWEEP gpu_fast_b256 --preset fast --batch-size 256 \
                --timeout 70 ;;
        sweepdef)
            phase sweepdef 300 $SWEEP gpu_default --preset default --batch-size 256 \
                --timeout 140 ;;
        sweepdefbs)
            phase sweepdef64 170 $SWEEP gpu_default_b64 --preset default --batch-size 64 \
                --repeats 1 --timeout 120
            phase sweepdef256 170 $SWEEP gpu_default_b256 --preset default --batch-size 256 \
                --repeats 1 --timeout 120 ;;
        sweepdef1)
            phase sweepdef1 150 $SWEEP gpu_default_b1 --preset default --batch-size 1 \
                --repeats 1 --timeout 70 ;;
        sweepdefgrad)
            phase sweepdefgrad 330 $SWEEP gpu_default_grad --preset default --batch-size 256 \
                --modes grad --repeats 1 --timeout 320 ;;
        speed)
            phase speed 540 $PY benchmarks/accuracy_speed.py --tag gpu \
                --only baseline fast default ;;
        *) echo "unknown phase $name" | tee -a "$LOG" ;;
    esac
done
save
