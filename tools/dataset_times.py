#!/usr/bin/env python3
"""Wall time of the shots of a `pixguide dataset` folder that its index (shots.jsonl) lists.

Each shot's shot.json is written last, so a shot took (its shot.json mtime) − (the previous
completion, or the start of its run). Give the start time of every run (epoch seconds) when the
folder was made by several runs (resumes); shots made but not in the index (e.g. from a run with
more --shots) count only as the previous completion of the next shot.

usage: tools/dataset_times.py DIR [RUN_START_EPOCH ...]
"""
import glob, json, os, sys

root, starts = sys.argv[1], [float(x) for x in sys.argv[2:]]
listed = {json.loads(l)["dir"] for l in open(os.path.join(root, "shots.jsonl"))}
done = sorted((os.path.getmtime(f), os.path.relpath(os.path.dirname(f), root))
              for f in glob.glob(os.path.join(root, "*", "*", "shot.json")))
total, per_scene, prev = 0.0, {}, None
for t, d in done:
    began = max([s for s in starts if s <= t] + ([prev] if prev is not None else []))
    prev = t
    if d in listed:
        total += t - began
        scene = os.path.basename(d).rsplit("_", 1)[0]
        per_scene[scene] = per_scene.get(scene, 0.0) + t - began
n = sum(1 for t, d in done if d in listed)
print(f"{n} of {len(listed)} listed shots: {total:.0f} s = {total / 60:.1f} min, {total / max(n, 1):.1f} s/shot")
for scene, s in sorted(per_scene.items(), key=lambda x: -x[1]):
    print(f"  {scene}: {s:.0f} s")
