#!/usr/bin/env python3
"""Weighted average of two weight files of the same model (a "model soup", Wortsman et al. 2022,
"Model soups: averaging weights of multiple fine-tuned models improves accuracy without
increasing inference time"): out = alpha * A + (1 - alpha) * B, tensor by tensor.

Both files must come from `pixguide train` with the same method, preset and widths (f16 or f32
tensors, not `pixguide quantize`'s 8-bit ones), and should be fine-tunes of one parent, which
is what makes their average a good model. The output keeps A's metadata except the provenance,
which records this command, both inputs' provenance, the summed steps and wall time, and the
validation relMSE given with --val (measure it; docs/denoiser.md says how the shipped one was).

  tools/average_weights.py A.safetensors B.safetensors --alpha 0.3 --val 0.0245 -o OUT.safetensors

Standard library only. The tensors are deterministic: the same inputs and alpha give the same
tensor bytes (each mean is computed in double precision and rounded to the file's float type
by struct's 'e'/'f' packing); only the provenance's date differs between runs.
"""
import argparse
import datetime
import json
import struct
import subprocess
import sys

FORMATS = {"F16": "e", "F32": "f"}


def load(path):
    with open(path, "rb") as f:
        data = f.read()
    (n,) = struct.unpack("<Q", data[:8])
    header = json.loads(data[8 : 8 + n])
    return header, data[8 + n :]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--alpha", type=float, required=True, help="weight of A (B gets 1 - alpha)")
    ap.add_argument("--val", type=float, required=True, help="validation relMSE of the result")
    ap.add_argument("-o", "--output", required=True)
    args = ap.parse_args()
    if not 0.0 <= args.alpha <= 1.0:
        sys.exit(f"--alpha {args.alpha}: must be in [0, 1]")
    ha, da = load(args.a)
    hb, db = load(args.b)
    ma, mb = ha.pop("__metadata__", {}), hb.pop("__metadata__", {})
    for key in ("pixguide.method", "pixguide.preset", "pixguide.config", "pixguide.format"):
        if ma.get(key) != mb.get(key):
            sys.exit(f"{args.a} and {args.b} differ in {key}: not the same model")
    if set(ha) != set(hb):
        sys.exit(f"{args.a} and {args.b} hold different tensors")
    out = bytearray(da)
    for name, ta in ha.items():
        tb = hb[name]
        if ta["dtype"] not in FORMATS or tb["dtype"] != ta["dtype"] or ta["shape"] != tb["shape"]:
            sys.exit(f"tensor {name}: {ta['dtype']}{ta['shape']} vs {tb['dtype']}{tb['shape']} (f16/f32 of one shape only)")
        fmt = FORMATS[ta["dtype"]]
        (s, e), (s2, e2) = ta["data_offsets"], tb["data_offsets"]
        n = (e - s) // struct.calcsize(fmt)
        x = struct.unpack(f"<{n}{fmt}", da[s:e])
        y = struct.unpack(f"<{n}{fmt}", db[s2:e2])
        out[s:e] = struct.pack(f"<{n}{fmt}", *[args.alpha * p + (1.0 - args.alpha) * q for p, q in zip(x, y)])
    pa, pb = json.loads(ma["pixguide.provenance"]), json.loads(mb["pixguide.provenance"])
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    prov = {
        "command": " ".join(["tools/average_weights.py"] + sys.argv[1:]),
        "seed": pa.get("seed", 0),
        "dataset": pa.get("dataset", ""),
        "wall_time_s": pa.get("wall_time_s", 0.0) + pb.get("wall_time_s", 0.0),
        "validation_rel_mse": args.val,
        "steps": pa.get("steps", 0) + pb.get("steps", 0),
        "git_commit": commit,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "notes": f"model soup: {args.alpha} x A + {1.0 - args.alpha} x B; A = {json.dumps(pa)}; B = {json.dumps(pb)}",
    }
    ma["pixguide.provenance"] = json.dumps(prov)
    ha["__metadata__"] = ma
    header = json.dumps(ha).encode()
    header += b" " * ((8 - len(header) % 8) % 8)
    with open(args.output, "wb") as f:
        f.write(struct.pack("<Q", len(header)) + header + bytes(out))
    print(f"wrote {args.output}: {args.alpha} x {args.a} + {1.0 - args.alpha} x {args.b}")


if __name__ == "__main__":
    main()
