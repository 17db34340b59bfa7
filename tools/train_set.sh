#!/usr/bin/env bash
# Trains one set of g, p and guided within a 90-minute budget, the way the
# 2026-11-27 morning set was trained (docs/journal/training.md): g and p side by side
# on one thread each, then guided from them on two threads. Every run is resumable
# (`--resume`): rerunning this script continues where a killed run stopped.
#
#   tools/train_set.sh DATA OUT            # e.g. tools/train_set.sh data/train-set runs/set
#
# Environment (defaults in brackets):
#   PIXGUIDE   the binary [target/release/pixguide]; a `--features tch` build for BACKEND=tch
#   BACKEND    flex or tch [tch]: tch is 2.5× faster per step here (docs/training-tch.md)
#   PRESET     [edge-noise]
#   G_MIN, P_MIN, GUIDED_MIN   wall-clock caps in minutes [35, 40, 14]
#   G_STEPS, P_STEPS, GUIDED_STEPS   step counts, which set the cosine schedules [2900, 360, 180]
#   BOTH_MIN, BOTH_STEPS       if BOTH_MIN is set, the both-buffers column is trained last
set -euo pipefail
data=${1:?dataset folder}
out=${2:?output folder}
bin=${PIXGUIDE:-target/release/pixguide}
backend=${BACKEND:-tch}
preset=${PRESET:-edge-noise}
# The loss of g, both and the joint stage: each patch's L1 plus a relative L2 term, divided by
# its input's error (docs/journal/denoiser.md, "L1 plus a relative L2 term"); p keeps the relative L1,
# on which it is better at 32-64 spp. The joint stage moves the pretrained columns at 1e-5 (the
# preset's 5e-5 made guided worse than both its columns on a caustic scene; docs/denoiser.md).
inside=(--loss-scale relative-to-input --rel-l2-weight 1 --rel-l2-inside)
relative=(--loss-scale relative-to-input)
common=(--backend "$backend" --data "$data" --preset "$preset" --patch 96 --batch 2 --resume --quiet)
mkdir -p "$out"
train() { # name threads args...
    local name=$1 threads=$2
    shift 2
    OMP_NUM_THREADS=$threads nice "$bin" --threads "$threads" train "${common[@]}" -o "$out/$name.safetensors" "$@" \
        >>"$out/$name.out" 2>&1
}
if [ ! -s "$out/g.safetensors" ] || [ ! -s "$out/p.safetensors" ]; then
    [ -s "$out/g.safetensors" ] || train g 1 --method g "${inside[@]}" --lr-branches 1e-3 --branch-steps "${G_STEPS:-2900}" \
        --finetune-steps 0 --val-every 200 --minutes "${G_MIN:-35}" &
    [ -s "$out/p.safetensors" ] || train p 1 --method p "${relative[@]}" --lr-branches 5e-4 --branch-steps "${P_STEPS:-360}" \
        --finetune-steps 0 --val-every 60 --minutes "${P_MIN:-40}" &
    wait
fi
[ -s "$out/guided.safetensors" ] || train guided 2 --method guided "${inside[@]}" --from-g "$out/g.safetensors" \
    --from-p "$out/p.safetensors" --joint-steps "${GUIDED_STEPS:-180}" --lr-joint-rest 1e-5 --val-every 40 --minutes "${GUIDED_MIN:-14}"
if [ -n "${BOTH_MIN:-}" ] && [ ! -s "$out/both.safetensors" ]; then
    train both 2 --method both "${inside[@]}" --lr-branches 3e-4 --branch-steps "${BOTH_STEPS:-400}" --finetune-steps 0 \
        --val-every 50 --minutes "$BOTH_MIN"
fi
tail -n 2 "$out"/*.out
