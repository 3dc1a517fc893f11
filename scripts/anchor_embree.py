#!/usr/bin/env python3
"""Embree 4 anchor for the mesh backend: traces the exact camera rays of a mesh scene with
Embree's single-ray rtcIntersect1 and with marchmesh, interleaved, 1 thread, Mrays/s.

The mesh is framed as crates/mesh/benches/bvh.rs frames it (500x500, 40 deg). The rays and
the render-space triangles (world minus camera position in f64, then f32) come from the
`anchor_rays` example, so both sides trace identical f32 data (docs: shared ANCHORS.md).

Setup:  python3 -m venv /tmp/embree-venv && /tmp/embree-venv/bin/pip install embreex numpy
Run:    /tmp/embree-venv/bin/python scripts/anchor_embree.py MESH.obj [MESH...] [--rounds 3]
            [--repeats 15] [--bvh bvh2,wide1,wide,raw] [--json OUT.json]
(scripts/anchor_embree.sh runs it on the committed meshes and writes bench-results/anchors/.)
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
import importlib.metadata
import json
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


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def git_commit():
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, check=True, capture_output=True, text=True
        )
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def load_average():
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def anchor_mesh(mesh, kinds, rounds, repeats):
    """Times Embree and each marchmesh tracer on MESH's camera rays in `rounds` interleaved
    rounds; prints the table and returns the mesh's record for --json."""
    with tempfile.TemporaryDirectory() as d:
        print(run_example("export", mesh, d).strip(), file=sys.stderr)
        tris = np.fromfile(os.path.join(d, "tris.f32"), dtype="<f4").reshape(-1, 3, 3)
        rays = np.fromfile(os.path.join(d, "rays.f32"), dtype="<f4").reshape(-1, 6)
    origins = np.ascontiguousarray(rays[:, :3])
    dirs = np.ascontiguousarray(rays[:, 3:])
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, tris)
    per = {"embree": [], **{k: [] for k in kinds}}
    hits = {}
    for r in range(rounds):
        e, hits["embree"] = embree_round(scene, origins, dirs, repeats)
        per["embree"].append(e)
        line = f"round {r}: embree {e:.2f} ({hits['embree']} hits)"
        for k in kinds:
            lines = run_example("time", mesh, k, str(repeats)).split()
            m = statistics.median(float(x) for x in lines[0::2])
            per[k].append(m)
            hits[k] = int(lines[1])
            line += f"  {k} {m:.2f} ({lines[1]} hits)"
        print(line, file=sys.stderr)
    emb = statistics.median(per["embree"])
    print(f"mesh: {mesh}  triangles: {len(tris)}  rays: {len(origins)}  threads: 1")
    print(f"{'tracer':<10} {'Mrays/s':>8} {'x Embree':>9}")
    print(f"{'embree':<10} {emb:>8.2f} {1.0:>9.3f}")
    record = {
        # Relative to the repository when inside it, else absolute (e.g. the full dragon).
        "mesh": (
            rel
            if not (rel := os.path.relpath(os.path.abspath(mesh), ROOT)).startswith("..")
            else os.path.abspath(mesh)
        ),
        "triangles": len(tris),
        "rays": len(origins),
        "embree": {"mrays_per_s_rounds": per["embree"], "mrays_per_s_median": emb},
        "embree_hits": hits["embree"],
        "tracers": {},
    }
    for k in kinds:
        ratios = [m / e for m, e in zip(per[k], per["embree"])]
        ratio = statistics.median(ratios)
        print(f"{k:<10} {statistics.median(per[k]):>8.2f} {ratio:>9.3f}")
        record["tracers"][k] = {
            "mrays_per_s_rounds": per[k],
            "mrays_per_s_median": statistics.median(per[k]),
            "ratio_over_embree_per_round_median": ratio,
            "hits": hits[k],
        }
    return record


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mesh", nargs="+", help="OBJ/PLY/glTF meshes, each anchored in turn")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument(
        "--bvh",
        default="bvh2,wide1,wide,raw",
        help="marchmesh tracers: bvh2, cwbvh, wide1 (single rays), wide (row packets), wide4x2 "
        "(4x2-tile packets), wide8 (row batches, no packets), raw (obvhs Bvh2)",
    )
    ap.add_argument(
        "--json",
        metavar="PATH",
        help="also write every figure (per round) as JSON, the format `marchmesh bench "
        "--anchor` and `marchmesh findings --anchor` read; refuses to overwrite a file",
    )
    a = ap.parse_args()
    if a.rounds < 1 or a.repeats < 1:
        ap.error("--rounds and --repeats must be at least 1")
    if a.json and os.path.lexists(a.json):
        ap.error(f"--json {a.json}: exists (nothing was overwritten)")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    kinds = [k for k in a.bvh.split(",") if k]
    start = time.time()
    load_start = load_average()
    meshes = [anchor_mesh(m, kinds, a.rounds, a.repeats) for m in a.mesh]
    load_end = load_average()
    print("load average:", load_end)
    if a.json:
        try:
            embree_version = "embreex " + importlib.metadata.version("embreex")
        except importlib.metadata.PackageNotFoundError:
            embree_version = "embreex (version unknown)"
        record = {
            "tool": "anchor-embree",
            "embree_version": embree_version,
            "unix_time": int(start),
            "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(start)),
            "cpu": cpu_model(),
            "git_commit": git_commit(),
            "load_average_start": load_start,
            "load_average_end": load_end,
            "threads": 1,
            "rounds": a.rounds,
            "repeats": a.repeats,
            "protocol": "per mesh and round: Embree rtcIntersect1 (1 warm-up, REPEATS timed, "
            "median), then each marchmesh tracer in a fresh anchor_rays process (build, 1 "
            "warm-up, REPEATS timed, median); thread CPU time on both sides; ratios are "
            "medians of per-round ratios",
            "meshes": meshes,
        }
        with open(a.json, "x") as f:
            json.dump(record, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
