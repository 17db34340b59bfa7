#!/usr/bin/env python3
"""Interim evaluation until `pixguide eval` exists: every held-out test scene (scenes/test.txt)
rendered at each spp, denoised in process by each shipped model, scored against its 8000-spp
reference by `pixguide render --reference` (relMSE with tone map (a), 1-SSIM; method.md §7.3).
Prints a markdown table (per scene and mean) to stdout.

usage: tools/quick_eval.py [--spp 2,4,8] [--models g,p,guided] [--seed 4242]
"""
import argparse, json, re, subprocess, sys
from pathlib import Path

root = Path(__file__).resolve().parent.parent
ap = argparse.ArgumentParser()
ap.add_argument("--spp", default="2,4,8")
ap.add_argument("--models", default="g,p,guided")
ap.add_argument("--seed", default="4242")
ap.add_argument("--bin", default=str(root / "target/release/pixguide"))
a = ap.parse_args()
line = re.compile(r"^\s*(noisy|denoised): relMSE ([0-9.eE+-]+) \(gamma [0-9.eE+-]+\), 1-SSIM ([0-9.eE+-]+)")
scenes = [l.strip() for l in (root / "scenes/test.txt").read_text().splitlines() if l.strip() and not l.startswith("#")]
rows = {}  # (scene, spp, method) -> (relmse, ssim, seconds)
for s in scenes:
    name = s.split("/")[0]
    ref = root / f"scenes/references/{name}.json"
    meta = json.loads(ref.read_text())
    for spp in a.spp.split(","):
        for m in a.models.split(","):
            cmd = [a.bin, "render", str(root / "scenes" / s), "--size", f"{meta['width']}x{meta['height']}", "--spp", spp,
                   "--seed", a.seed, "--denoise", m, "--reference", str(root / f"scenes/references/{name}.exr"),
                   "-o", "/tmp/quick_eval.exr", "-q"]
            out = subprocess.run(cmd, capture_output=True, text=True)
            if out.returncode != 0:
                sys.exit(f"{' '.join(cmd)}\n{out.stderr}")
            t = re.search(r"denoise \(.*?\): ([0-9.]+) s", out.stdout)
            for l in out.stdout.splitlines():
                g = line.match(l)
                if g:
                    key = "noisy" if g.group(1) == "noisy" else m
                    rows[(name, spp, key)] = (float(g.group(2)), float(g.group(3)), float(t.group(1)) if t and key != "noisy" else 0.0)
            print(f"{name} {spp} spp {m}: done", file=sys.stderr)
methods = ["noisy"] + a.models.split(",")
for metric, idx in (("relMSE (tone map (a))", 0), ("1-SSIM", 1)):
    print(f"\n### {metric}\n")
    for spp in a.spp.split(","):
        print(f"\n{spp} spp\n\n| scene | " + " | ".join(methods) + " |\n|---|" + "---|" * len(methods))
        means = {m: [] for m in methods}
        for s in scenes:
            name = s.split("/")[0]
            vals = [rows[(name, spp, m)][idx] for m in methods]
            for m, v in zip(methods, vals):
                means[m].append(v)
            print(f"| {name} | " + " | ".join(f"{v:.4f}" for v in vals) + " |")
        print("| **mean** | " + " | ".join(f"**{sum(v)/len(v):.4f}**" for v in means.values()) + " |")
