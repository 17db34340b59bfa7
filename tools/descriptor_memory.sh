#!/bin/bash
# Peak memory of render --denoise guided for two pixguide binaries side by side (e.g. before and
# after a change to how descriptors are held): process max RSS (/usr/bin/time) and the binary's
# own report (render, preprocess, peak heap above the frame). The images must be identical.
#   tools/descriptor_memory.sh OLD_BINARY NEW_BINARY [SIZE=512] [SPP=64]
set -e
cd "$(dirname "$0")/.."
old=$1; new=$2; size=${3:-512}; spp=${4:-64}
for b in "$old" "$new"; do
  out=$(mktemp -d)
  /usr/bin/time -f "max RSS %M KB, wall %e s" "$b" render scenes/cornell-box/scene.toml --size ${size}x${size} --spp $spp \
    --denoise guided -o $out/img.exr -q 2>&1 | grep -E "^render:|^denoise|max RSS" | sed "s|^|$(basename $b): |"
  sha256sum $out/img.exr | cut -c1-16
  rm -rf $out
done
