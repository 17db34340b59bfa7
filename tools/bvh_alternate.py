#!/usr/bin/env python3
"""Two or more builds of `bvh_ab` against Embree, run in turn, process after process.

For a change that cannot be switched at run time (a new field, a different layout), the
in-process A/B of `renderer/examples/bvh_ab.rs` cannot hold both versions; this runs each
binary in turn, N rounds, and prints per round and binary the ratio of our variant's median
rate to Embree's (`e`) median in that same process, so that the host's drift between
processes divides out. docs/performance.md quotes it as `altb` / `bvh_alternate.py`.

    cargo build --release -p renderer --example bvh_ab && cp target/release/examples/bvh_ab /tmp/old
    # ...change, rebuild, cp to /tmp/new...
    MESH=sphere REPS=5 python3 tools/bvh_alternate.py /tmp/old,/tmp/new "e 5" 4

The environment (MESH, SPHERE_N, REPS, ...) is passed to every run. The arguments must hold
`e` and one variant of ours.
"""
import os
import re
import statistics
import subprocess
import sys


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    bins = sys.argv[1].split(",")
    args = sys.argv[2].split()
    rounds = int(sys.argv[3])
    ours = [v for v in args if v != "e"]
    if "e" not in args or len(ours) != 1:
        sys.exit("the variants must be `e` and exactly one of ours, e.g. \"e 5\"")
    ours = ours[0]
    sets = ("camera", "random")
    ratios = {b: {s: [] for s in sets} for b in bins}
    line = re.compile(r"(\w+) (camera|random) \[(\S+)\]: best ([\d.]+) median ([\d.]+)")
    for i in range(rounds):
        for b in bins:
            run = subprocess.run([b] + args, capture_output=True, text=True, env=os.environ)
            if run.returncode != 0:
                sys.exit(f"{b} failed:\n{run.stderr}")
            med = {(m[2], m[3]): float(m[5]) for m in line.finditer(run.stdout)}
            parts = []
            for s in sets:
                if (s, ours) not in med or (s, "e") not in med:
                    sys.exit(f"{b}: no {s} rates for {ours} and e in its output:\n{run.stdout}")
                r = med[(s, ours)] / med[(s, "e")]
                ratios[b][s].append(r)
                parts.append(f"{s} {med[(s, ours)]:.2f}/{med[(s, 'e')]:.2f}={r:.3f}")
            print(i, os.path.basename(b), " ".join(parts), flush=True)
    for b in bins:
        print(b, " ".join(f"{s} median {statistics.median(ratios[b][s]):.3f} [{' '.join(f'{x:.3f}' for x in ratios[b][s])}]" for s in sets))


if __name__ == "__main__":
    main()
