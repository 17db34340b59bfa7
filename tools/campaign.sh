#!/usr/bin/env bash
# The long training campaign that made the shipped p, both and ablations, run a sitting at a
# time (docs/journal/training.md, "The campaign"). Each model is one run with a fixed plan of
# steps (which fixes its learning-rate curve), paused when the sitting's time is up and resumed
# in the next, on this machine from its local checkpoint or on another from the packed one
# kept in KEEP.
#
#   tools/campaign.sh DATA RUNS MINUTES   # e.g. tools/campaign.sh data/campaign runs/campaign 150
#
# Two lanes, one thread each, so both cores work all session:
#   lane 1: g, then both (which needs nothing from g), then Fix-N-Train and Full-N-Full;
#   lane 2: p, then guided (from the finished g and p: it waits for g if p ends first), then
#           radiance-only. The ablations wait for guided, whose step rate plans them.
# An ablation starts only if its whole plan fits in the session's remaining time at the step
# rate its parent run measured, so it never needs a packed checkpoint. At the end of the
# session every unfinished run is packed (`pixguide
# checkpoint pack`) into denoiser/weights/campaign/<model>.ckpt and every finished one's
# weights and log are copied there; commit that folder.
#
# Environment (defaults in brackets):
#   PIXGUIDE  the binary [target/release/pixguide]; a `--features tch` build for BACKEND=tch
#             (its LibTorch is found in target/torch-venv when LD_LIBRARY_PATH does not name one)
#   BACKEND   flex or tch [tch]      PRESET [edge-noise]      KEEP [denoiser/weights/campaign]
#   G_STEPS, P_STEPS, BOTH_STEPS, GUIDED_STEPS   planned steps [12000, 1500, 1500, 1000]
#   ABLATION_STEPS (fix-n-train, radiance-only), SCRATCH_STEPS (full-n-full)   [500, 1000]
set -euo pipefail
data=${1:?dataset folder}
runs=${2:?run folder}
minutes=${3:?minutes this session may use}
bin=${PIXGUIDE:-target/release/pixguide}
backend=${BACKEND:-tch}
preset=${PRESET:-edge-noise}
keep=${KEEP:-denoiser/weights/campaign}
deadline=$(($(date +%s) + minutes * 60))
torch_lib=target/torch-venv/lib/python3.11/site-packages/torch/lib
if [ "$backend" != flex ] && [ -d "$torch_lib" ] && [[ "${LD_LIBRARY_PATH:-}" != *torch* ]]; then
    export LD_LIBRARY_PATH="$PWD/$torch_lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
# The allocator: tools/allocator.sh. JEMALLOC=lane1 or lane2 for one lane only, none for glibc.
source "$(dirname "$0")/allocator.sh"
# The shipped recipe's losses (tools/train_set.sh, docs/denoiser.md): g, both and the joint
# stage weigh each patch's L1 plus a relative L2 term by the input's error; p the relative L1.
inside=(--loss-scale relative-to-input --rel-l2-weight 1 --rel-l2-inside)
relative=(--loss-scale relative-to-input)
common=(--backend "$backend" --data "$data" --preset "$preset" --patch 96 --batch 2 --resume --quiet --finetune-steps 0)
mkdir -p "$runs" "$keep"
models=(g p both guided fix-n-train radiance-only full-n-full)

left() { echo $(((deadline - $(date +%s)) / 60)); }
done_() { [ -s "$runs/$1.safetensors" ]; }
# A checkpoint committed by an earlier session on another machine continues here.
for m in "${models[@]}"; do
    if ! done_ "$m" && [ ! -e "$runs/$m.safetensors.ckpt/state.json" ] && [ -e "$keep/$m.ckpt/state.json" ]; then
        "$bin" checkpoint unpack "$keep/$m.ckpt" -o "$runs/$m.safetensors.ckpt"
    fi
    if done_ "$m" || [ -e "$runs/$m.safetensors" ] || [ ! -e "$keep/$m.safetensors" ]; then continue; fi
    cp "$keep/$m.safetensors" "$keep/$m.safetensors.log.jsonl" "$runs/"
done
train() { # name args...
    local name=$1
    shift
    done_ "$name" && return 0
    local m
    m=$(left)
    [ "$m" -ge 2 ] || return 0
    OMP_NUM_THREADS=1 nice "$bin" --threads 1 train "${common[@]}" -o "$runs/$name.safetensors" \
        --session-minutes "$m" "$@" >>"$runs/$name.out" 2>&1
}
# Minutes `steps` steps take at the mean s/step of a finished run (its log's step lines) times a
# factor in percent, plus 3 for loading the data: a float product, rounded up once.
plan_minutes() { # log steps factor_percent
    python3 -c "import json,math,sys; s=[d['seconds'] for d in map(json.loads, open(sys.argv[1])) if d.get('event') == 'step' and d.get('seconds')]; print(math.ceil(int(sys.argv[2]) * sum(s) / max(len(s), 1) * int(sys.argv[3]) / 100 / 60) + 3)" "$1" "$2" "$3"
}
# Starts an ablation only if its plan fits: steps × (parent's s/step × factor) < time left.
ablation() { # name steps parent factor_percent args...
    local name=$1 steps=$2 parent=$3 factor=$4
    shift 4
    done_ "$name" && return 0
    if [ ! -e "$runs/$name.safetensors.ckpt/state.json" ]; then
        local need
        need=$(plan_minutes "$runs/$parent.safetensors.log.jsonl" "$steps" "$factor")
        if [ "$need" -gt "$(left)" ]; then
            echo "$name: needs ~$need min, $(left) left: next session" >>"$runs/$name.out"
            return 0
        fi
    fi
    train "$name" "$@"
}
from_gp=(--from-g "$runs/g.safetensors" --from-p "$runs/p.safetensors")
# Waits (while the session lasts) for the other lane to finish model $1; true if it did.
await() {
    while ! done_ "$1" && [ "$(left)" -ge 2 ]; do sleep 60; done
    done_ "$1"
}
lane1() {
    use_jemalloc lane1
    train g --method g "${inside[@]}" --lr-branches 1e-3 --branch-steps "${G_STEPS:-12000}" --val-every 500
    done_ g || return 0
    train both --method both "${inside[@]}" --lr-branches 3e-4 --branch-steps "${BOTH_STEPS:-1500}" --val-every 100
    done_ both && await guided || return 0
    # Fix-N-Train trains only E, the cheapest of the guided family: guided's rate bounds it.
    ablation fix-n-train "${ABLATION_STEPS:-500}" guided 100 --ablation fix-n-train "${inside[@]}" "${from_gp[@]}" \
        --joint-steps "${ABLATION_STEPS:-500}" --val-every 100
    # Full-N-Full: everything from scratch at the pretraining rate, a step as costly as guided's.
    ablation full-n-full "${SCRATCH_STEPS:-1000}" guided 110 --ablation full-n-full "${inside[@]}" \
        --scratch-steps "${SCRATCH_STEPS:-1000}" --val-every 100
}
lane2() {
    use_jemalloc lane2
    train p --method p "${relative[@]}" --lr-branches 5e-4 --branch-steps "${P_STEPS:-1500}" --val-every 100
    done_ p && await g || return 0
    train guided --method guided "${inside[@]}" "${from_gp[@]}" --joint-steps "${GUIDED_STEPS:-1000}" \
        --lr-joint-rest 1e-5 --val-every 100
    done_ guided || return 0
    ablation radiance-only "${ABLATION_STEPS:-500}" guided 100 --ablation radiance-only "${inside[@]}" "${from_gp[@]}" \
        --joint-steps "${ABLATION_STEPS:-500}" --lr-joint-rest 1e-5 --val-every 100
}
lane1 &
lane2 &
wait
for m in "${models[@]}"; do
    if done_ "$m"; then
        cp "$runs/$m.safetensors" "$runs/$m.safetensors.log.jsonl" "$keep/"
        rm -rf "$keep/$m.ckpt" "$keep/$m.log.jsonl"
    elif [ -e "$runs/$m.safetensors.ckpt/state.json" ]; then
        rm -rf "$keep/$m.ckpt"
        "$bin" checkpoint pack "$runs/$m.safetensors.ckpt" -o "$keep/$m.ckpt"
        cp "$runs/$m.safetensors.log.jsonl" "$keep/$m.log.jsonl" 2>/dev/null || true
    fi
done
du -sh "$keep"
tail -n 2 "$runs"/*.out
