#!/usr/bin/env bash
# Equal-time comparison of the two column backbones (issue: "decide by measurement"): the KPCN
# of the `default` preset against the multi-scale kernel-predicting U-Net of `mskp`, for one
# method, trained side by side on one thread each so that both see the same machine load.
# Each runs at its own highest stable peak rate (docs/training.md, "Learning rate") with the
# warm-up + cosine shape, no finetune stage, and validates about once a minute; the
# validation events carry wall time, and `pixguide plot-training` draws the curves.
#
#   tools/backbone_race.sh METHOD DATA OUT MINUTES KPCN_STEPS MSKP_STEPS
#   e.g. tools/backbone_race.sh g /work/data/train-set /work/data/race 20 1600 2600
#
# The step counts should fill MINUTES at the measured seconds per step (a short run of each
# prints its s/step); --minutes caps each run in case the machine is slower than that.
set -euo pipefail
method=${1:?method}
data=${2:?dataset folder}
out=${3:?output folder}
minutes=${4:?minutes}
kpcn_steps=${5:?KPCN steps}
mskp_steps=${6:?MSKP steps}
bin=${PIXGUIDE:-target/release/pixguide}
mkdir -p "$out"
run() {
    local preset=$1 lr=$2 steps=$3
    local every=$(( steps / 16 ))
    nice "$bin" --threads 1 train --data "$data" --method "$method" --preset "$preset" \
        -o "$out/$method-$preset.safetensors" --lr-branches "$lr" --branch-steps "$steps" \
        --finetune-steps 0 --val-every "$every" --minutes "$minutes" --quiet \
        >"$out/$method-$preset.out" 2>&1
}
run default 3e-4 "$kpcn_steps" &
run mskp 1e-3 "$mskp_steps" &
wait
tail -n 1 "$out/$method-default.out" "$out/$method-mskp.out"
