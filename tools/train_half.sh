#!/bin/bash
# The half-size comparison models: the shipped `edge-noise` U-Net columns at half
# the channels of every level (`--widths 12,16,24,32,40` against 24,32,48,64,80), trained on the
# campaign's dataset with the campaign's losses and rates (tools/campaign.sh) for fewer steps:
#   g       3000 steps at 1e-3 (L1 + relative L2, relative to the input), then a tone-mapped
#           finetune of 600 steps at 1e-4 (the shipped g's finetune, docs/denoiser.md);
#   p        600 steps at 5e-4 (relative L1);
#   guided   100 joint steps from them (lr 1e-5 for the columns and PathNets), where the
#           campaign's guided and every later joint run had its best validation.
# g and p run side by side (two lanes, THREADS threads each; tools/campaign.sh's layout, since
# two one-thread runs use two cores better than one two-thread run), then guided alone with both
# lanes' threads. Deterministic from the seed whatever THREADS is; rerunning resumes from the
# checkpoints. Each run's output goes to OUT/<model>.out.
#
#   tools/train_half.sh DATA OUT     # e.g. tools/train_half.sh data/campaign runs/half
#
# Environment: PIXGUIDE (the binary, a `--features tch` build for BACKEND=tch)
# [target/release/pixguide], BACKEND [tch], THREADS [1] (per lane), JEMALLOC [all; none for glibc].
# The half files shipped until 2026-11-29 are the KPCN half models of 2026-11-23 (preset `half`),
# made by this script's earlier version (git log -p tools/train_half.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
P=${PIXGUIDE:-target/release/pixguide}
D=${1:?dataset folder}
W=${2:?output folder}
backend=${BACKEND:-tch}
threads=${THREADS:-1}
mkdir -p "$W"
torch_lib=target/torch-venv/lib/python3.11/site-packages/torch/lib
if [ "$backend" != flex ] && [ -d "$torch_lib" ] && [[ "${LD_LIBRARY_PATH:-}" != *torch* ]]; then
    export LD_LIBRARY_PATH="$PWD/$torch_lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
source tools/allocator.sh # jemalloc where installed; JEMALLOC=none for glibc
use_jemalloc all
common=(--backend "$backend" --data "$D" --preset edge-noise --widths 12,16,24,32,40 --patch 96 --batch 2 --seed 1 --resume)
inside=(--loss-scale relative-to-input --rel-l2-weight 1 --rel-l2-inside)
run() { local t=$1; shift; OMP_NUM_THREADS=$t nice "$P" --threads "$t" train "${common[@]}" "$@"; }
run "$threads" -o "$W/g-half.safetensors" --method g "${inside[@]}" --lr-branches 1e-3 --branch-steps 3000 \
    --finetune-steps 600 --finetune-loss tonemapped --lr-finetune 1e-4 --val-every 200 >"$W/g-half.out" 2>&1 &
g_pid=$!
run "$threads" -o "$W/p-half.safetensors" --method p --loss-scale relative-to-input --lr-branches 5e-4 \
    --branch-steps 600 --finetune-steps 0 --val-every 100 >"$W/p-half.out" 2>&1 || { kill "$g_pid"; exit 1; }
wait "$g_pid" || { echo "g-half failed: $W/g-half.out" >&2; exit 1; }
run $((2 * threads)) -o "$W/guided-half.safetensors" --method guided "${inside[@]}" --from-g "$W/g-half.safetensors" \
    --from-p "$W/p-half.safetensors" --joint-steps 100 --lr-joint-rest 1e-5 --val-every 50 >"$W/guided-half.out" 2>&1
