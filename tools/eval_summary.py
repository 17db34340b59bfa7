#!/usr/bin/env python3
"""Mean relMSE and 1-SSIM at 2/4/8 spp (raw / normalised by each scene's 2-spp noisy error) from a
`pixguide eval` cache, as markdown (the tables of docs/denoiser.md).

usage: tools/eval_summary.py docs/results/cache.jsonl noisy,g,p,both,guided,...
"""
import json, sys, collections
recs = [json.loads(l) for l in open(sys.argv[1]) if '"quality"' in l]
methods = sys.argv[2].split(",")
spps = [2, 4, 8]
q = {}
for r in recs:
    q[(r["scene"], r["spp"], r["method"])] = r
scenes = sorted({r["scene"] for r in recs})
for metric, name in (("rel_mse", "relMSE"), ("one_minus_ssim", "1−SSIM")):
    print(f"\n{name}, mean over the {len(scenes)} test scenes (raw / normalised by the scene's 2-spp noisy error):\n")
    print("| method | " + " | ".join(f"{s} spp" for s in spps) + " |")
    print("|---|" + "---|" * len(spps))
    for m in methods:
        cells = []
        for s in spps:
            rows = [(q[(sc, s, m)][metric], q[(sc, 2, "noisy")][metric]) for sc in scenes if (sc, s, m) in q]
            if len(rows) < len(scenes):
                cells.append("–"); continue
            raw = sum(a for a, _ in rows) / len(rows)
            nrm = sum(a / b for a, b in rows) / len(rows)
            cells.append(f"{raw:.4f} / {nrm:.3f}")
        print(f"| {m} | " + " | ".join(cells) + " |")
