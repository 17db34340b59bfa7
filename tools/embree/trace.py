#!/usr/bin/env python3
"""Trace rays with Embree (through embreex) for pixguide's cross-check test and ray benchmark.

Usage: trace.py INPUT OUTPUT [fast|robust]

INPUT (little endian, written by renderer/src/bench.rs):
    magic   b"PGRT0001"
    u64     triangle count T, u64 ray count R
    f32     T*9 triangle vertices (x0 y0 z0 x1 y1 z1 x2 y2 z2 per triangle)
    f32     R*3 ray origins, R*3 ray directions, R ray tmax values

OUTPUT:
    magic   b"PGRH0002"
    u64     R
    f64     seconds spent in the Embree ray query only (scene build excluded), wall clock
    f64     seconds spent building the scene (the first query commits it)
    f64     CPU seconds of this thread spent in the ray query (time.thread_time: immune to other
            processes taking the CPU on a shared machine; the query runs on this one thread)
    i32     R primitive ids (-1 = miss)
    f32     R hit distances (tfar; meaningless on a miss)

embreex's `run` loops over the rays one at a time in a single thread (rtcIntersect1 in a Cython
loop), so Embree's figures here are single-thread figures; the caller scales them. The scene is
built with default quality; `fast` (the default) leaves out RTC_SCENE_FLAG_ROBUST (Embree's
fastest setting), `robust` sets it (watertight traversal and intersection, used by the
cross-check).
"""

import struct
import sys
import time

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh


def main() -> int:
    if len(sys.argv) not in (3, 4) or (len(sys.argv) == 4 and sys.argv[3] not in ("fast", "robust")):
        print(__doc__, file=sys.stderr)
        return 2
    with open(sys.argv[1], "rb") as f:
        data = f.read()
    if data[:8] != b"PGRT0001":
        print(f"{sys.argv[1]}: not a pixguide ray file", file=sys.stderr)
        return 2
    n_tris, n_rays = struct.unpack_from("<QQ", data, 8)
    off = 24
    tris = np.frombuffer(data, dtype="<f4", count=n_tris * 9, offset=off).reshape(n_tris, 3, 3)
    off += n_tris * 36
    origins = np.frombuffer(data, dtype="<f4", count=n_rays * 3, offset=off).reshape(n_rays, 3)
    off += n_rays * 12
    dirs = np.frombuffer(data, dtype="<f4", count=n_rays * 3, offset=off).reshape(n_rays, 3)
    off += n_rays * 12
    tmax = np.frombuffer(data, dtype="<f4", count=n_rays, offset=off)

    scene = rtcore_scene.EmbreeScene(robust=len(sys.argv) == 4 and sys.argv[3] == "robust")
    TriangleMesh(scene, np.ascontiguousarray(tris, dtype=np.float32))
    origins = np.ascontiguousarray(origins, dtype=np.float32)
    dirs = np.ascontiguousarray(dirs, dtype=np.float32)
    tmax = np.ascontiguousarray(tmax, dtype=np.float32).copy()

    # The first query commits (builds) the scene: time it separately with one ray.
    t0 = time.perf_counter()
    scene.run(origins[:1], dirs[:1], dists=tmax[:1].copy(), output=1)
    build = time.perf_counter() - t0

    t0 = time.perf_counter()
    c0 = time.thread_time()
    res = scene.run(origins, dirs, dists=tmax, output=1)
    query_cpu = time.thread_time() - c0
    query = time.perf_counter() - t0

    prim = np.ascontiguousarray(res["primID"], dtype="<i4")
    prim = np.where(prim < 0, -1, prim).astype("<i4")
    tfar = np.ascontiguousarray(res["tfar"], dtype="<f4")
    with open(sys.argv[2], "wb") as f:
        f.write(b"PGRH0002")
        f.write(struct.pack("<Qddd", n_rays, query, build, query_cpu))
        f.write(prim.tobytes())
        f.write(tfar.tobytes())
    return 0


if __name__ == "__main__":
    sys.exit(main())
