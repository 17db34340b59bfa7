#!/usr/bin/env python3
"""Scores a model and OIDN on every validation shot of a dataset, whole frames, one shot at a time.

Why: training's validation (and `pixguide plot-training --baselines`) reports the mean over shots,
and a few shots where one method fails badly can decide that mean. This prints each shot's
relMSE for the noisy input, the model and OIDN, as `pixguide denoise --reference` measures it
(the test metric of docs/results.md, whole frame), and the mean and the median over shots of
model / OIDN.

    python3 tools/val_per_shot.py DATA WEIGHTS [--model g] [--spp 2,8] [--bin target/release/pixguide]
"""
import argparse
import glob
import os
import re
import statistics
import subprocess
import tempfile

# `pixguide denoise --reference` prints the noisy and the denoised scores on lines like
# "    noisy: relMSE 0.05618 (gamma ...)" and " denoised: relMSE 0.00778 (gamma ...)".
SCORE = re.compile(r"^\s*(noisy|denoised): relMSE ([0-9.eE+-]+)", re.M)


def scores(binary, frame, reference, extra, out):
    """(noisy, denoised) relMSE of one `pixguide denoise` run."""
    r = subprocess.run([binary, "--threads", "1", "denoise", frame, *extra, "--reference", reference, "-o", out],
                       check=True, capture_output=True, text=True)
    found = dict((k, float(v)) for k, v in SCORE.findall(r.stdout + r.stderr))
    if set(found) != {"noisy", "denoised"}:
        raise SystemExit(f"{frame}: no scores in pixguide's output:\n{r.stdout}{r.stderr}")
    return found["noisy"], found["denoised"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data")
    ap.add_argument("weights")
    ap.add_argument("--model", default="g")
    ap.add_argument("--spp", default="2,8")
    ap.add_argument("--bin", default="target/release/pixguide")
    a = ap.parse_args()
    shots = sorted(glob.glob(os.path.join(a.data, "val", "*")))
    if not shots:
        raise SystemExit(f"{a.data}: no validation shots under val/")
    with tempfile.TemporaryDirectory() as tmp:
        for spp in [int(s) for s in a.spp.split(",")]:
            print(f"\n{spp} spp: relMSE, whole frame\n")
            print(f"| shot | noisy | {a.model} | OIDN | {a.model} / OIDN |\n|---|---:|---:|---:|---:|")
            ratios, means = [], {"noisy": [], a.model: [], "OIDN": []}
            for d in shots:
                frame = os.path.join(d, f"noisy_{spp}spp.exr")
                ref = os.path.join(d, "reference.exr")
                out = os.path.join(tmp, "out.exr")
                extra = ["--model", a.model, "--weights", a.weights]
                if a.model != "g":
                    # The dataset keeps one descriptor file of the most samples; a frame at N spp
                    # uses its first N samples (the shots are nested).
                    extra += ["--descriptors", max(glob.glob(os.path.join(d, "descriptors_*spp.safetensors")), key=len)]
                noisy, model = scores(a.bin, frame, ref, extra, out)
                _, oidn = scores(a.bin, frame, ref, ["--model", "oidn"], out)
                row = {"noisy": noisy, a.model: model, "OIDN": oidn}
                for k, v in row.items():
                    means[k].append(v)
                ratios.append(model / oidn)
                print(f"| {os.path.basename(d)} | {noisy:.4f} | {model:.5f} | {oidn:.5f} | {ratios[-1]:.2f} |")
            m = {k: statistics.fmean(v) for k, v in means.items()}
            print(
                f"| **mean** | {m['noisy']:.4f} | {m[a.model]:.5f} | {m['OIDN']:.5f} | {m[a.model] / m['OIDN']:.2f} (of the means); "
                f"median of the ratios {statistics.median(ratios):.2f} |"
            )


if __name__ == "__main__":
    main()
