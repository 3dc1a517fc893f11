#!/usr/bin/env python3
"""Embree 4 anchor for the mesh backend: traces the exact camera rays of a mesh scene with
Embree's single-ray rtcIntersect1 and with marchmesh, interleaved, 1 thread, Mrays/s.

The mesh is framed as crates/mesh/benches/bvh.rs frames it (500x500, 40 deg). The rays and
the render-space triangles (world minus camera position in f64, then f32) come from the
`anchor_rays` example, so both sides trace identical f32 data (docs: shared ANCHORS.md).

Setup:  python3 -m venv /tmp/embree-venv && /tmp/embree-venv/bin/pip install embreex numpy
Run:    /tmp/embree-venv/bin/python scripts/anchor_embree.py MESH.obj [--rounds 3]
            [--repeats 15] [--bvh bvh2,wide1,wide,raw]
Each round times Embree (1 warm-up, REPEATS timed, median) then each marchmesh BVH in a
fresh process (build, 1 warm-up, REPEATS timed, median); the ratios use per-round medians
(median over rounds), so load from other processes hits both sides alike. Both sides time
the CPU time of the tracing thread (Python's thread_time, CLOCK_THREAD_CPUTIME_ID in
anchor_rays: embreex calls rtcIntersect1 ray by ray on the calling thread), so time spent
descheduled on a loaded machine counts on neither side. (anchor_rays read
/proc/thread-self/schedstat before 2026-11-23, which advances only at 4 ms scheduler ticks:
its full-dragon repeats read either 6.94 or 7.81 Mrays/s, figures before then are coarse.)
embreex exposes neither rtcSetSceneBuildQuality nor a device config string, so Embree runs
its defaults (medium build quality; huge pages on Linux, per the rtcNewDevice docs). State the load
average printed at the end beside any figure quoted.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Honour CARGO_TARGET_DIR (relative paths are relative to the repository root, as cargo's).
TARGET = os.path.join(ROOT, os.environ.get("CARGO_TARGET_DIR", "target"))
EXAMPLE = os.path.join(TARGET, "release", "examples", "anchor_rays")


def run_example(*args):
    if not os.path.exists(EXAMPLE):
        subprocess.run(
            ["cargo", "build", "--release", "-p", "marchmesh-mesh", "--example", "anchor_rays"],
            cwd=ROOT,
            check=True,
        )
    out = subprocess.run([EXAMPLE, *args], check=True, capture_output=True, text=True)
    return out.stdout


def embree_round(scene, origins, dirs, repeats):
    scene.run(origins, dirs, output=1)  # warm-up
    rates, hits = [], 0
    for _ in range(repeats):
        t = time.thread_time()
        res = scene.run(origins, dirs, output=1)
        rates.append(len(origins) / (time.thread_time() - t) / 1e6)
        hits = int((res["geomID"] != -1).sum()) if "geomID" in res else -1
    return statistics.median(rates), hits


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mesh")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument(
        "--bvh",
        default="bvh2,wide1,wide,raw",
        help="marchmesh tracers: bvh2, cwbvh, wide1 (single rays), wide (row packets), wide4x2 "
        "(4x2-tile packets), wide8 (row batches, no packets), raw (obvhs Bvh2)",
    )
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory() as d:
        print(run_example("export", a.mesh, d).strip(), file=sys.stderr)
        tris = np.fromfile(os.path.join(d, "tris.f32"), dtype="<f4").reshape(-1, 3, 3)
        rays = np.fromfile(os.path.join(d, "rays.f32"), dtype="<f4").reshape(-1, 6)
    origins = np.ascontiguousarray(rays[:, :3])
    dirs = np.ascontiguousarray(rays[:, 3:])
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, tris)
    kinds = [k for k in a.bvh.split(",") if k]
    per = {"embree": [], **{k: [] for k in kinds}}
    for r in range(a.rounds):
        e, hits = embree_round(scene, origins, dirs, a.repeats)
        per["embree"].append(e)
        line = f"round {r}: embree {e:.2f} ({hits} hits)"
        for k in kinds:
            lines = run_example("time", a.mesh, k, str(a.repeats)).split()
            m = statistics.median(float(x) for x in lines[0::2])
            per[k].append(m)
            line += f"  {k} {m:.2f} ({lines[1]} hits)"
        print(line, file=sys.stderr)
    emb = statistics.median(per["embree"])
    print(f"mesh: {a.mesh}  triangles: {len(tris)}  rays: {len(origins)}  threads: 1")
    print(f"{'tracer':<10} {'Mrays/s':>8} {'x Embree':>9}")
    print(f"{'embree':<10} {emb:>8.2f} {1.0:>9.3f}")
    for k in kinds:
        ratios = [m / e for m, e in zip(per[k], per["embree"])]
        print(f"{k:<10} {statistics.median(per[k]):>8.2f} {statistics.median(ratios):>9.3f}")
    print("load average:", " ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
