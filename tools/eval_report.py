#!/usr/bin/env python3
"""Reports from a `pixguide eval` cache (docs/results/cache.jsonl or a run's own cache).

usage: tools/eval_report.py CACHE.jsonl [METHOD,...] [--normalised]

Default report: each method's mean relMSE over the test scenes at every
spp, with its ratio to OIDN's where OIDN was measured; the paper's Table 2 measure (each
scene's relMSE divided by its 2-spp noisy relMSE, averaged over scenes and 2-64 spp) and how
far guided is below both-buffers on it; and every (scene, spp) where a learned method is worse
than plain Monte Carlo at the same spp.

--normalised: the tables of docs/denoiser.md instead, mean relMSE and 1-SSIM at 2/4/8 spp,
each cell raw / normalised by the scene's 2-spp noisy error.
"""
import collections
import json
import sys

args = [a for a in sys.argv[1:] if not a.startswith("--")]
normalised = "--normalised" in sys.argv
recs = [json.loads(l) for l in open(args[0]) if '"quality"' in l]
rec = {(r["scene"], r["spp"], r["method"]): r for r in recs}
scenes = sorted({r["scene"] for r in recs})
spps = sorted({r["spp"] for r in recs})
methods = args[1].split(",") if len(args) > 1 else list(dict.fromkeys(r["method"] for r in recs))
BASELINES = ("noisy", "oidn")


def values(m, s, metric="rel_mse"):
    """The metric of method m at s spp on every scene, or None if a scene is missing."""
    v = [rec[(sc, s, m)][metric] for sc in scenes if (sc, s, m) in rec]
    return v if len(v) == len(scenes) else None


def mean(m, s, metric="rel_mse"):
    v = values(m, s, metric)
    return sum(v) / len(v) if v else None


def table2(m):
    """Mean over scenes and spp of relMSE / the scene's 2-spp noisy relMSE (the paper's Table 2)."""
    v = [rec[(sc, s, m)]["rel_mse"] / rec[(sc, 2, "noisy")]["rel_mse"] for sc in scenes for s in spps if (sc, s, m) in rec]
    return sum(v) / len(v) if len(v) == len(scenes) * len(spps) else None


def row(cells):
    print("| " + " | ".join(cells) + " |")


if normalised:
    for metric, name in (("rel_mse", "relMSE"), ("one_minus_ssim", "1−SSIM")):
        print(f"\n{name}, mean over the {len(scenes)} test scenes (raw / normalised by the scene's 2-spp noisy error):\n")
        row(["method"] + [f"{s} spp" for s in (2, 4, 8)])
        print("|---|" + "---|" * 3)
        for m in methods:
            cells = []
            for s in (2, 4, 8):
                v = values(m, s, metric)
                if v is None:
                    cells.append("–")
                    continue
                ref = [rec[(sc, 2, "noisy")][metric] for sc in scenes]
                cells.append(f"{sum(v) / len(v):.4f} / {sum(a / b for a, b in zip(v, ref)) / len(v):.3f}")
            row([m] + cells)
    sys.exit(0)

print(f"mean relMSE over {len(scenes)} scenes (× OIDN's in brackets)\n")
row(["method"] + [f"{s} spp" for s in spps] + ["Table 2"])
print("|---|" + "---|" * (len(spps) + 1))
for m in methods:
    cells = []
    for s in spps:
        a, o = mean(m, s), mean("oidn", s)
        cells.append("–" if a is None else f"{a:.4f}" + (f" ({a / o:.2f}×)" if o and m != "oidn" else ""))
    t = table2(m)
    row([m] + cells + ["–" if t is None else f"{t:.3f}"])
oidn = {s: mean("oidn", s) for s in (2, 4, 8)}
if all(oidn.values()):
    row(["floor (guided ≤ 1.5× OIDN)"] + [f"{1.5 * oidn[s]:.4f}" if s in oidn else "" for s in spps] + [""])
g, b = table2("guided"), table2("both")
if g and b:
    print(f"\nTable 2 measure: guided {g:.3f}, both {b:.3f}: guided {100 * (1 - g / b):.0f} % below both (floor: 10 %)")

worse = collections.defaultdict(list)
for (sc, s, m), r in sorted(rec.items()):
    if m in BASELINES or m not in methods or (sc, s, "noisy") not in rec:
        continue
    n = rec[(sc, s, "noisy")]["rel_mse"]
    if r["rel_mse"] > n:
        worse[m].append(f"{sc}@{s} ({r['rel_mse']:.5f} vs noisy {n:.5f})")
print("\nworse than noisy:")
for m in methods:
    if m not in BASELINES:
        print(f"- {m}: " + ("; ".join(worse[m]) if worse[m] else "none"))
