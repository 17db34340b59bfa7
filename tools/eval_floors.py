#!/usr/bin/env python3
"""Issue 16's floors from a `pixguide eval` cache: each method's mean relMSE over the test scenes
at every spp (with its ratio to OIDN where OIDN was measured), and every (scene, spp, method)
whose relMSE is above plain Monte Carlo's at the same spp.

usage: tools/eval_floors.py CACHE.jsonl [METHOD,...]   (default: every method in the cache)
"""
import collections
import json
import sys

recs = [json.loads(l) for l in open(sys.argv[1]) if '"quality"' in l]
q = {(r["scene"], r["spp"], r["method"]): r["rel_mse"] for r in recs}
scenes = sorted({r["scene"] for r in recs})
spps = sorted({r["spp"] for r in recs})
present = list(dict.fromkeys(r["method"] for r in recs))
methods = sys.argv[2].split(",") if len(sys.argv) > 2 else present
floors = {2: 0.0265, 4: 0.0187, 8: 0.0143}


def mean(m, s):
    v = [q[(sc, s, m)] for sc in scenes if (sc, s, m) in q]
    return sum(v) / len(v) if len(v) == len(scenes) else None


print(f"mean relMSE over {len(scenes)} scenes (× OIDN's in brackets)\n")
print("| method | " + " | ".join(f"{s} spp" for s in spps) + " |")
print("|---|" + "---|" * len(spps))
for m in methods:
    cells = []
    for s in spps:
        a, o = mean(m, s), mean("oidn", s)
        cells.append("–" if a is None else f"{a:.4f}" + (f" ({a / o:.2f}×)" if o and m != "oidn" else ""))
    print(f"| {m} | " + " | ".join(cells) + " |")
print("| floor (guided) | " + " | ".join(f"{floors[s]:.4f}" if s in floors else "" for s in spps) + " |")

worse = collections.defaultdict(list)
for (sc, s, m), v in sorted(q.items()):
    if m in ("noisy", "oidn") or m not in methods or (sc, s, "noisy") not in q:
        continue
    if v > q[(sc, s, "noisy")]:
        worse[m].append(f"{sc}@{s} ({v:.5f} vs noisy {q[(sc, s, 'noisy')]:.5f})")
print("\nworse than noisy:")
for m in methods:
    if m in ("noisy", "oidn"):
        continue
    print(f"- {m}: " + ("; ".join(worse[m]) if worse[m] else "none"))
