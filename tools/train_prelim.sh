#!/bin/bash
set -e
cd "$(dirname "$0")/.."
P=target/release/pixguide
D=${1:-data/prelim}
$P train --data $D --method g --branch-steps 400 --finetune-steps 50 --seed 1 --minutes 9 -o denoiser/weights/g-default.safetensors
$P train --data $D --method p --branch-steps 250 --finetune-steps 30 --seed 1 --minutes 13 -o denoiser/weights/p-default.safetensors
$P train --data $D --method guided --from-g denoiser/weights/g-default.safetensors --from-p denoiser/weights/p-default.safetensors --joint-steps 150 --lr-joint-e 1e-4 --seed 1 --minutes 10 -o denoiser/weights/guided-default.safetensors
