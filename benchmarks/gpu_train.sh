#!/usr/bin/env bash
# One-lease GPU training of DGSE-S: a time-boxed dataset, the paper preset on
# the GPU, and the new weights against the shipped ones on unseen layouts.
# Results of one run: benchmarks/results/gpu_training/README.md.
#
#   W=/tmp/gpu CODE=src EVAL_PAPER=eval-paper.h5 setsid nohup bash benchmarks/gpu_train.sh > /tmp/gpu/pipeline.log 2>&1 &
#
# Steps (times from the start of this script):
#  1. dgse generate --size SIZE_MIN SIZE_MAX --seed SEED with GEN_WORKERS workers and a
#     large --layouts, interrupted (SIGINT, as a Ctrl-C) after GEN_SECONDS: the layouts
#     finished by then are committed and the fixed val/test sensor configurations of
#     the stored layouts are drawn (dgse.data.generation._finalize, as generate does at
#     its end), so the store is complete for its stored layouts.
#  2. In the background, the shipped DGSE-S (--model default) is evaluated on the
#     first EVAL_LIMIT test cases of that store and on the first EVAL_LIMIT cases of
#     the train split of EVAL_PAPER (a store of paper-size maps with another seed;
#     no model has seen it), on the GPU.
#  3. dgse train --config configs/train/paper.yaml on the GPU (bf16-mixed) with
#     --max-time MAX_TIME, exporting the best checkpoint.
#  4. The new weights are evaluated like the shipped ones in 2 (EVAL_LIMIT can be
#     changed while it runs by writing a number into $W/eval_limit).
# TRAIN_ARGS adds options to 3 (e.g. "--set batch_size=4" for a quick check on a CPU).
# EVAL=0 skips 2 and 4 (the whole lease trains; evaluate on a CPU afterwards).
# dgse runs through a small wrapper that restores Python's Ctrl-C handler (a
# background job ignores SIGINT) and turns on cudnn.benchmark (fixed shapes).
set -u
W=${W:-/tmp/gpu}
CODE=${CODE:-$PWD/src}
SEED=${SEED:-1}
SIZE_MIN=${SIZE_MIN:-5}
SIZE_MAX=${SIZE_MAX:-16}
GEN_LAYOUTS=${GEN_LAYOUTS:-20000}
GEN_SECONDS=${GEN_SECONDS:-390}
GEN_WORKERS=${GEN_WORKERS:-16}
CONFIG=${CONFIG:-configs/train/paper.yaml}
MAX_TIME=${MAX_TIME:-00:15:30}
TRAIN_WORKERS=${TRAIN_WORKERS:-12}
CONFIGS_PER_ENV=${CONFIGS_PER_ENV:-15}
VAL_CONFIGS_PER_ENV=${VAL_CONFIGS_PER_ENV:-5}
EVAL_PAPER=${EVAL_PAPER:-}
EVAL_LIMIT=${EVAL_LIMIT:-120}
ACCEL=${ACCEL:-gpu}
PRECISION=${PRECISION:-bf16-mixed}
EVAL_DEVICE=${EVAL_DEVICE:-cuda}
EVAL=${EVAL:-1}
OBS="5 20 50 150 300"

mkdir -p "$W"
cp "$CONFIG" "$W/train-config.yaml"
[ -n "$EVAL_PAPER" ] && cp "$EVAL_PAPER" "$W/eval-paper.h5"
export PYTHONPATH="$CODE${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
T0=$(date +%s)
stamp() { echo "[$(date +%T) +$(( $(date +%s) - T0 ))s] $*"; }
# the dgse CLI with Ctrl-C handling restored (and cudnn.benchmark for train/evaluate);
# run as python3 -c "$WRAP" so that $! of a background job is the Python process
WRAP="import signal,sys; signal.signal(signal.SIGINT, signal.default_int_handler); sys.argv[0]='dgse'; from dgse.cli.main import main; main()"
dgse_gpu() { python3 -c "import signal,sys,torch; signal.signal(signal.SIGINT, signal.default_int_handler); torch.backends.cudnn.benchmark=True; sys.argv[0]='dgse'; from dgse.cli.main import main; main()" "$@"; }

evaluate() {  # MODEL NAME: both evaluations of one model, in parallel; waits for them
    local model=$1 name=$2 limit=$EVAL_LIMIT
    [ -s "$W/eval_limit" ] && limit=$(cat "$W/eval_limit")
    stamp "evaluate $name (limit $limit)"
    dgse_gpu evaluate "$W/data.h5" --split test --method dgse-s --model "$model" --observations $OBS \
        --trials 2 --limit "$limit" --device "$EVAL_DEVICE" --threads 1 --no-progress \
        --json "$W/eval-$name-test.json" > "$W/eval-$name-test.log" 2>&1 &
    local p1=$!
    if [ -s "$W/eval-paper.h5" ]; then
        dgse_gpu evaluate "$W/eval-paper.h5" --split train --method dgse-s --model "$model" --observations $OBS \
            --trials 2 --limit "$limit" --device "$EVAL_DEVICE" --threads 1 --no-progress \
            --json "$W/eval-$name-paper.json" > "$W/eval-$name-paper.log" 2>&1
    fi
    wait $p1
    stamp "evaluate $name done"
}

# 1. data, time-boxed
stamp "generate: --size $SIZE_MIN $SIZE_MAX --seed $SEED, $GEN_WORKERS workers, for ${GEN_SECONDS}s"
# in a session of its own (setsid: no fork here, so $! is the Python process and the
# id of its process group, which holds the Dask workers too)
setsid python3 -c "$WRAP" generate --layouts "$GEN_LAYOUTS" --workers "$GEN_WORKERS" --seed "$SEED" \
    --size "$SIZE_MIN" "$SIZE_MAX" --out "$W/data.h5" --checkpoint 30 --no-progress > "$W/generate.log" 2>&1 &
gpid=$!
while kill -0 $gpid 2>/dev/null && [ $(( $(date +%s) - T0 )) -lt "$GEN_SECONDS" ]; do sleep 2; done
# A Ctrl-C first (it commits what is staged); on the H100 run the KeyboardInterrupt
# landed in a weakref callback ("Exception ignored") and generation went on, so after
# GEN_GRACE seconds the whole group is killed: the store survives kill -9 (finished
# layouts wait in its journal, which _finalize below commits).
kill -INT $gpid 2>/dev/null
for _ in $(seq "${GEN_GRACE:-20}"); do kill -0 $gpid 2>/dev/null || break; sleep 1; done
kill -KILL -- -$gpid 2>/dev/null
wait $gpid 2>/dev/null
stamp "generate stopped"
python3 - "$W/data.h5" "$SEED" "$W/data-summary.json" <<'EOF' || { stamp "finalize failed"; exit 1; }
import json, sys
from pathlib import Path
from dgse.data.generation import _finalize
from dgse.data.store import DatasetStore
store, seed, out = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
_finalize(store, seed, 30)
with DatasetStore(store, "r") as s:
    splits = s.splits
    info = {"n_layouts": len(s), "n_failures": len(s.failures()),
            "splits": {k: len(v) for k, v in splits.items()}, "layouts": {}}
    for lid in s.layouts():
        li = s.layout_info(lid)
        info["layouts"][lid] = [li["split"], li["summary"]["width_m"], li["summary"]["height_m"]]
json.dump(info, open(out, "w"))
print({k: v for k, v in info.items() if k != "layouts"})
EOF
stamp "store finalized"

# 2. the shipped model, while training runs
epid=
[ "$EVAL" = 1 ] && { ( evaluate default shipped ) > "$W/eval-shipped.out" 2>&1 & epid=$!; }

# 3. training
stamp "train: $CONFIG, max-time $MAX_TIME"
dgse_gpu train --config "$W/train-config.yaml" --data "$W/data.h5" --out "$W/run" --accelerator "$ACCEL" --devices 1 \
    --precision "$PRECISION" --max-time "$MAX_TIME" --workers "$TRAIN_WORKERS" --seed "$SEED" \
    --set configs_per_env="$CONFIGS_PER_ENV" --set val_configs_per_env="$VAL_CONFIGS_PER_ENV" \
    --set log_every_n_steps=20 ${TRAIN_ARGS:-} --export "$W/dgse-s-gpu.safetensors" --no-progress > "$W/train.log" 2>&1
stamp "train exited with $?"
cat "$W/train.log"

# 4. the new model
if [ "$EVAL" = 1 ]; then
    wait $epid
    evaluate "$W/dgse-s-gpu.safetensors" new
fi
stamp "pipeline done"
touch "$W/DONE"
