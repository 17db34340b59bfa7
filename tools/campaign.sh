#!/usr/bin/env bash
# The long training campaign of issue 12, run a session at a time (docs/training.md, "The
# campaign"). Each model is one run with a fixed plan of steps (which fixes its learning-rate
# curve), paused when the session's time is up and resumed in the next session, on this
# machine from its local checkpoint or on another from the packed one committed in
# denoiser/weights/campaign/.
#
#   tools/campaign.sh DATA RUNS MINUTES   # e.g. tools/campaign.sh /work/data/campaign /work/runs/campaign 150
#
# Phase 1: g and p side by side (one thread each). Phase 2, once both are done: both and
# guided (from the finished g and p) side by side. Phase 3: the ablations. At the end of the session every unfinished
# run is packed (`pixguide checkpoint pack`) into denoiser/weights/campaign/<model>.ckpt and
# every finished one's weights and log are copied there; commit that folder.
#
# Environment (defaults in brackets):
#   PIXGUIDE  the binary [target/release/pixguide]; a `--features tch` build for BACKEND=tch
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
# The shipped recipe's losses (tools/train_set.sh, docs/denoiser.md): g, both and the joint
# stage weigh each patch's L1 plus a relative L2 term by the input's error; p the relative L1.
inside=(--loss-scale relative-to-input --rel-l2-weight 1 --rel-l2-inside)
relative=(--loss-scale relative-to-input)
common=(--backend "$backend" --data "$data" --preset "$preset" --patch 96 --batch 2 --resume --quiet --finetune-steps 0)
mkdir -p "$runs" "$keep"

left() { echo $(((deadline - $(date +%s)) / 60)); }
done_() { [ -s "$runs/$1.safetensors" ]; }
# A checkpoint committed by an earlier session on another machine continues here.
for m in g p both guided fix-n-train radiance-only full-n-full; do
    if ! done_ "$m" && [ ! -e "$runs/$m.safetensors.ckpt/state.json" ] && [ -e "$keep/$m.ckpt/state.json" ]; then
        "$bin" checkpoint unpack "$keep/$m.ckpt" -o "$runs/$m.safetensors.ckpt"
    fi
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
train g --method g "${inside[@]}" --lr-branches 1e-3 --branch-steps "${G_STEPS:-12000}" --val-every 500 &
train p --method p "${relative[@]}" --lr-branches 5e-4 --branch-steps "${P_STEPS:-1500}" --val-every 100 &
wait
from_gp=(--from-g "$runs/g.safetensors" --from-p "$runs/p.safetensors")
if done_ g && done_ p; then
    train both --method both "${inside[@]}" --lr-branches 3e-4 --branch-steps "${BOTH_STEPS:-1500}" --val-every 100 &
    train guided --method guided "${inside[@]}" "${from_gp[@]}" --joint-steps "${GUIDED_STEPS:-1000}" \
        --lr-joint-rest 1e-5 --val-every 100 &
    wait
fi
# Phase 3: the ablations of the paper's Table 2 on the same data, shorter (issue 12 allows it),
# two at a time. Fix-N-Train and radiance-only start from the campaign's g and p; Full-N-Full
# trains everything from scratch at the pretraining rate.
if done_ g && done_ p && done_ both && done_ guided; then
    train fix-n-train --ablation fix-n-train "${inside[@]}" "${from_gp[@]}" --joint-steps "${ABLATION_STEPS:-500}" --val-every 100 &
    train radiance-only --ablation radiance-only "${inside[@]}" "${from_gp[@]}" --joint-steps "${ABLATION_STEPS:-500}" \
        --lr-joint-rest 1e-5 --val-every 100 &
    wait
    train full-n-full --ablation full-n-full "${inside[@]}" --scratch-steps "${SCRATCH_STEPS:-1000}" --val-every 100
fi
for m in g p both guided fix-n-train radiance-only full-n-full; do
    if done_ "$m"; then
        cp "$runs/$m.safetensors" "$runs/$m.safetensors.log.jsonl" "$keep/"
        rm -rf "$keep/$m.ckpt"
    elif [ -e "$runs/$m.safetensors.ckpt/state.json" ]; then
        rm -rf "$keep/$m.ckpt"
        "$bin" checkpoint pack "$runs/$m.safetensors.ckpt" -o "$keep/$m.ckpt"
        cp "$runs/$m.safetensors.log.jsonl" "$keep/$m.log.jsonl" 2>/dev/null || true
    fi
done
du -sh "$keep"
tail -n 2 "$runs"/*.out
