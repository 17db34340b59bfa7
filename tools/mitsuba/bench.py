"""Times Mitsuba 3's path integrator for `pixguide bench` (src/cli/bench.rs), run by run
alternating with pixguide's own integrator, so that both see the same load on a shared machine.

    python bench.py SCENE.xml WIDTH HEIGHT SPP MAX_DEPTH THREADS VARIANT

VARIANT is `llvm_ad_rgb` or `scalar_rgb`. If `llvm_ad_rgb` cannot run (Dr.Jit finds no libLLVM;
pixguide points DRJIT_LIBLLVM_PATH at one when it finds it), `scalar_rgb` is used instead and
the reason is reported. The scene is prepared exactly as for the cross-check (render.py's
`prepared_xml`: WIDTH x HEIGHT hdrfilm with a box filter, independent sampler with SPP samples),
and rendered by a `path` integrator with MAX_DEPTH and no Russian roulette, on THREADS threads.

Protocol, one JSON object per line on stdout:
- after loading, one untimed warm-up render (seed 0) so that Dr.Jit's tracing and LLVM
  compilation of the kernels are done before any timed run:
  {"variant", "fallback_reason", "version", "threads", "warmup_seconds", "load_seconds"}
- then for each line `render SEED` on stdin, one timed render:
  {"seconds", "cpu_seconds", "compiled_kernels", "mean"} where `seconds` is the wall time of
  `mi.render` until the image is evaluated, `cpu_seconds` the CPU time of the whole process (all
  its threads) meanwhile, `compiled_kernels` counts kernels Dr.Jit had to compile (rather than
  take from its cache) during that render (0 means no JIT time was timed), and `mean` is the
  image's mean RGB (a check that both renderers saw the same scene);
- EOF or `quit` ends the process.
"""
import json
import os
import sys
import time

import drjit as dr
import mitsuba as mi

from render import prepared_xml


def pick_variant(wanted):
    if wanted == "scalar_rgb":
        mi.set_variant("scalar_rgb")
        return "scalar_rgb", None
    try:
        mi.set_variant(wanted)
        # The LLVM backend initialises lazily: evaluate something to find out whether it works.
        x = mi.Float(1.0) + 1.0
        dr.eval(x)
        return wanted, None
    except Exception as e:  # noqa: BLE001 — any failure here means "no LLVM backend"
        reason = str(e).strip().splitlines()[-1] if str(e).strip() else type(e).__name__
        mi.set_variant("scalar_rgb")
        return "scalar_rgb", f"{wanted} unavailable: {reason}"


def emit(obj):
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def main():
    if len(sys.argv) != 8:
        raise SystemExit(__doc__)
    path = sys.argv[1]
    width, height, spp, max_depth, threads = (int(a) for a in sys.argv[2:7])
    variant, reason = pick_variant(sys.argv[7])
    dr.set_thread_count(threads)
    jit = variant.startswith("llvm")
    if jit:
        dr.set_flag(dr.JitFlag.KernelHistory, True)
    t0 = time.perf_counter()
    text, base = prepared_xml(path, width, height, spp)
    mi.file_resolver().prepend(base)
    scene = mi.load_string(text)
    integrator = mi.load_dict({"type": "path", "max_depth": max_depth, "rr_depth": max_depth + 1, "hide_emitters": False})
    load_seconds = time.perf_counter() - t0

    def render(seed):
        if jit:
            dr.kernel_history()  # clears the history: only this render's kernels are counted
        start, cpu_start = time.perf_counter(), time.process_time()
        img = mi.render(scene, integrator=integrator, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        arr = img.numpy()
        seconds = time.perf_counter() - start
        cpu_seconds = time.process_time() - cpu_start
        compiled = 0
        if jit:
            compiled = sum(1 for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT and not k.get("cache_hit", False))
        mean = [float(arr[:, :, c].mean()) for c in range(3)]
        return seconds, cpu_seconds, compiled, mean

    warmup, _, _, _ = render(0)
    emit({"variant": variant, "fallback_reason": reason, "version": mi.__version__, "threads": dr.thread_count(), "warmup_seconds": warmup, "load_seconds": load_seconds})
    for line in sys.stdin:
        words = line.split()
        if not words or words[0] == "quit":
            break
        if words[0] != "render" or len(words) != 2:
            raise SystemExit(f"bench.py: unexpected command {line.strip()!r}")
        seconds, cpu_seconds, compiled, mean = render(int(words[1]))
        emit({"seconds": seconds, "cpu_seconds": cpu_seconds, "compiled_kernels": compiled, "mean": mean})


if __name__ == "__main__":
    main()
