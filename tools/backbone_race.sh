#!/usr/bin/env bash
# Equal-time comparison of the two column backbones (issue: "decide by measurement"): the KPCN
# of the `kpcn` preset against the multi-scale kernel-predicting U-Net of `default`, for one
# method, trained side by side on one thread each so that both see the same machine load.
# Each runs at its own highest stable peak rate (docs/journal/training.md, "Learning rate") with the
# warm-up + cosine shape, no finetune stage, and validates about once a minute; the
# validation events carry wall time, and `pixguide plot-training` draws the curves.
#
#   [VALS=16] tools/backbone_race.sh METHOD DATA OUT MINUTES KPCN_STEPS MSKP_STEPS
#   e.g. tools/backbone_race.sh g data/train-set runs/race 21 1600 2600
#        VALS=6 tools/backbone_race.sh p data/train-set runs/race 21 320 1000
#
# VALS validations per run: a P-buffer model's validation (19 shots at up to 32 spp) takes about
# a minute on one thread, so p runs validate less often than g runs.
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
    local every=$(( steps / ${VALS:-16} ))
    nice "$bin" --threads 1 train --data "$data" --method "$method" --preset "$preset" \
        -o "$out/$method-$preset.safetensors" --lr-branches "$lr" --branch-steps "$steps" \
        --finetune-steps 0 --val-every "$every" --minutes "$minutes" --quiet \
        >"$out/$method-$preset.out" 2>&1
}
run kpcn 3e-4 "$kpcn_steps" &
run default 1e-3 "$mskp_steps" &
wait
tail -n 1 "$out/$method-kpcn.out" "$out/$method-default.out"
