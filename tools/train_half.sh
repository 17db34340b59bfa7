#!/bin/bash
# The half-size comparison models (preset `half`: 50 % of the default preset's channels), each
# given the same number of steps per stage as its default-size twin got in the shipped
# `train --all --minutes 48` run (g 306 + 23, p 186 + 10, guided 132), so the two sizes differ
# only in width. Deterministic from the seed; rerunning resumes from the checkpoints.
set -e
cd "$(dirname "$0")/.."
P=${PIXGUIDE:-target/release/pixguide}
D=${1:-data/train-set}
W=denoiser/weights
$P train --data $D --method g --preset half --branch-steps 306 --finetune-steps 23 --seed 1 --resume -o $W/g-half.safetensors
$P train --data $D --method p --preset half --branch-steps 186 --finetune-steps 10 --seed 1 --resume -o $W/p-half.safetensors
$P train --data $D --method guided --preset half --from-g $W/g-half.safetensors --from-p $W/p-half.safetensors \
  --joint-steps 132 --lr-joint-e 1e-4 --seed 1 --resume -o $W/guided-half.safetensors
