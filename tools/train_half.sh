#!/bin/bash
# The half-size comparison models (preset `half`: 50 % of the default preset's channels), each
# given the steps of its default-size twin (the 2026-11-25 U-Net runs: g 2600, p 500, guided
# 170, no finetune stage; `train --all`'s plan), so the two sizes differ only in width.
# Deterministic from the seed; rerunning resumes from the checkpoints.
#
# The half files shipped today are still the KPCN half models of 2026-11-23, made by this
# script's earlier version (git log -p tools/train_half.sh); they are to be retrained with it.
set -e
cd "$(dirname "$0")/.."
P=${PIXGUIDE:-target/release/pixguide}
D=${1:-data/train-set}
W=${2:-denoiser/weights}
$P train --data $D --method g --preset half --branch-steps 2600 --finetune-steps 0 --seed 1 --resume -o $W/g-half.safetensors
$P train --data $D --method p --preset half --branch-steps 500 --finetune-steps 0 --seed 1 --resume -o $W/p-half.safetensors
$P train --data $D --method guided --preset half --from-g $W/g-half.safetensors --from-p $W/p-half.safetensors \
  --joint-steps 170 --seed 1 --resume -o $W/guided-half.safetensors
