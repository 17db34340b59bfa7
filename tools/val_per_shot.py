#!/usr/bin/env python3
"""Scores a model and OIDN on every validation shot of a dataset, whole frames, one shot at a time.

Why: training's validation (and `pixguide plot-training --baselines`) reports the mean over shots,
and a few shots where one method fails badly can decide that mean. This prints each shot's
relMSE (the test metric: tone map (a) of method.md §7.3, eps 1e-4, whole frame) for the noisy
input, the model and OIDN, and the mean and the median over shots of model / OIDN.

    target/mitsuba-venv/bin/python tools/val_per_shot.py DATA WEIGHTS [--model g] [--spp 2,8]

Needs the Mitsuba venv that `pixguide bench` installs (numpy, and mitsuba to read EXR) and a
release build of pixguide; the denoised frames go to a temporary folder.
"""
import argparse
import glob
import os
import subprocess
import tempfile

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")


def load(path):
    return np.array(mi.Bitmap(path))[..., :3].astype(np.float64)


def tone_map(c):
    c = np.maximum(c, 0.0)
    lum = 0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]
    return np.clip((c / (1.0 + lum[..., None] / 1.5)) ** (1.0 / 2.2), 0.0, 1.0)


def rel_mse(x, y):
    x, y = tone_map(x), tone_map(y)
    return float(((x - y) ** 2 / (y**2 + 1e-4)).mean())


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
                ref = load(os.path.join(d, "reference.exr"))
                out = {}
                for label, extra in ((a.model, ["--model", a.model, "--weights", a.weights]), ("OIDN", ["--model", "oidn"])):
                    o = os.path.join(tmp, f"{label}.exr")
                    subprocess.run([a.bin, "--threads", "1", "denoise", frame, *extra, "-o", o], check=True, capture_output=True)
                    out[label] = rel_mse(load(o), ref)
                out["noisy"] = rel_mse(load(frame), ref)
                for k, v in out.items():
                    means[k].append(v)
                ratios.append(out[a.model] / out["OIDN"])
                print(f"| {os.path.basename(d)} | {out['noisy']:.4f} | {out[a.model]:.5f} | {out['OIDN']:.5f} | {ratios[-1]:.2f} |")
            m = {k: np.mean(v) for k, v in means.items()}
            print(
                f"| **mean** | {m['noisy']:.4f} | {m[a.model]:.5f} | {m['OIDN']:.5f} | {m[a.model] / m['OIDN']:.2f} (of the means); "
                f"median of the ratios {np.median(ratios):.2f} |"
            )


if __name__ == "__main__":
    main()
