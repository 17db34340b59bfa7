#!/bin/bash
# The half-size comparison models (preset `half`: 50 % of the default preset's channels), each
# given the steps and rates of its default-size twin (the swap runs of 2026-11-25 afternoon:
# g 2900 + 400 tone-mapped finetune, p 600 at 5e-4, guided 200; docs/denoiser.md), so the two
# sizes differ only in width.
# Deterministic from the seed; rerunning resumes from the checkpoints.
#
# The half files shipped today are still the KPCN half models of 2026-11-23, made by this
# script's earlier version (git log -p tools/train_half.sh); they are to be retrained with it.
set -e
cd "$(dirname "$0")/.."
P=${PIXGUIDE:-target/release/pixguide}
D=${1:-data/train-set}
W=${2:-denoiser/weights}
$P train --data $D --method g --preset half --branch-steps 2900 --finetune-steps 400 --seed 1 --resume -o $W/g-half.safetensors
$P train --data $D --method p --preset half --lr-branches 5e-4 --branch-steps 600 --finetune-steps 0 --seed 1 --resume -o $W/p-half.safetensors
$P train --data $D --method guided --preset half --from-g $W/g-half.safetensors --from-p $W/p-half.safetensors \
  --joint-steps 200 --seed 1 --resume -o $W/guided-half.safetensors
