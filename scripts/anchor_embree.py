#!/usr/bin/env python3
"""Embree 4 anchor for the mesh backend: traces the exact camera rays of a mesh scene with
Embree's single-ray rtcIntersect1 and with marchmesh, interleaved, 1 thread, Mrays/s.

The mesh is framed as crates/mesh/benches/bvh.rs frames it (500x500, 40 deg). The rays and
the render-space triangles (world minus camera position in f64, then f32) come from the
`anchor_rays` example, so both sides trace identical f32 data (docs: shared ANCHORS.md).

Setup:  python3 -m venv /tmp/embree-venv && /tmp/embree-venv/bin/pip install embreex numpy
        (and a C compiler, `cc`, on the PATH)
Run:    /tmp/embree-venv/bin/python scripts/anchor_embree.py MESH.obj [MESH...] [--rounds 3]
            [--repeats 15] [--bvh bvh2,wide1,wide,raw] [--embree-quality medium|high]
            [--embree-robust] [--embree-packets] [--json OUT.json]
(scripts/anchor_embree.sh runs it on the committed meshes and writes bench-results/anchors/.)

Embree runs in a C loop (scripts/embree_trace.c, compiled here with `cc` against the
libembree4 inside the embreex wheel): one rtcIntersect1 call per ray, Embree's default scene
flags and build quality unless --embree-robust / --embree-quality say otherwise. Before
2026-11-26 the anchor timed embreex's own `EmbreeScene.run` instead, which sets
RTC_SCENE_FLAG_ROBUST (embreex's default, not Embree's) and fills six NumPy output arrays per
call: Embree measured 0.70-0.74x its C-loop speed on the bunny and 0.86-0.89x on the full
dragon that way, so every ratio to Embree before then is too high by that factor. Per mesh,
embreex still traces the rays once with the same flags, as a check: the C loop's hit
distances must equal embreex's bit for bit (at medium quality), else the script stops.

Each round times Embree (1 warm-up, REPEATS timed, median) then each marchmesh BVH in a
fresh process (build, 1 warm-up, REPEATS timed, median); the ratios use per-round medians
(median over rounds), so load from other processes hits both sides alike. Both sides time
the CPU time of the tracing thread (CLOCK_THREAD_CPUTIME_ID on both sides), so time spent
descheduled on a loaded machine counts on neither side. (anchor_rays read
/proc/thread-self/schedstat before 2026-11-23, which advances only at 4 ms scheduler ticks:
its full-dragon repeats read either 6.94 or 7.81 Mrays/s, figures before then are coarse.)
State the load average printed at the end beside any figure quoted.
"""

import argparse
import ctypes
import glob
import importlib.metadata
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import embreex
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


QUALITY = {"low": 0, "medium": 1, "high": 2}  # RTCBuildQuality
ROBUST_FLAG = 4  # RTC_SCENE_FLAG_ROBUST


class EmbreeLoop:
    """scripts/embree_trace.c compiled into `workdir` and bound to the wheel's libembree4."""

    def __init__(self, workdir):
        libs = glob.glob(
            os.path.join(os.path.dirname(embreex.__file__), "..", "embreex.libs", "libembree4*")
        )
        if not libs:
            sys.exit("anchor_embree: no libembree4 in the embreex wheel (embreex.libs/)")
        # Global, so the loop's Embree symbols resolve against the wheel's library.
        ctypes.CDLL(libs[0], mode=ctypes.RTLD_GLOBAL)
        so = os.path.join(workdir, "embree_trace.so")
        src = os.path.join(ROOT, "scripts", "embree_trace.c")
        cc = os.environ.get("CC", "cc")
        try:
            subprocess.run([cc, "-O2", "-fPIC", "-shared", "-o", so, src], check=True)
        except (OSError, subprocess.CalledProcessError) as e:
            sys.exit(f"anchor_embree: compiling {src} with `{cc}` failed ({e}); set CC")
        lib = ctypes.CDLL(so)
        lib.anchor_build.restype = ctypes.c_void_p
        lib.anchor_build.argtypes = [
            ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
            ctypes.POINTER(ctypes.c_int),
        ]
        lib.anchor_trace.restype = ctypes.c_long
        lib.anchor_trace.argtypes = [
            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int,
            ctypes.POINTER(ctypes.c_double), ctypes.c_void_p,
        ]
        lib.anchor_trace8.restype = ctypes.c_long
        lib.anchor_trace8.argtypes = lib.anchor_trace.argtypes
        lib.anchor_release.argtypes = [ctypes.c_void_p]
        self.lib = lib

    def build(self, tris, quality, flags):
        """A scene of `tris` (n x 3 x 3 float32, C order); exits on an Embree error."""
        err = ctypes.c_int(0)
        scene = self.lib.anchor_build(tris.ctypes.data, len(tris), quality, flags, err)
        if not scene:
            sys.exit(f"anchor_embree: Embree scene build failed (code {err.value})")
        return scene

    def trace(self, scene, rays, repeats, packets=False):
        """(median Mrays/s, hit count, hit distances) of `rays` (n x 6 float32): one
        rtcIntersect1 per ray, or with `packets` one rtcIntersect8 per 8 consecutive rays."""
        run = self.lib.anchor_trace8 if packets else self.lib.anchor_trace
        rates = (ctypes.c_double * repeats)()
        t = np.empty(len(rays), dtype=np.float32)
        hits = run(scene, rays.ctypes.data, len(rays), repeats, rates, t.ctypes.data)
        return statistics.median(rates), int(hits), t

    def release(self, scene):
        self.lib.anchor_release(scene)


def tile_order(side, height, tw, th):
    """Ray indices of a row-major `side x height` image, tile by tile (`tw x th` tiles,
    row-major inside and between tiles; a ragged edge keeps what fits), as anchor_rays'
    `wide4x2` orders them."""
    order = []
    for ty in range(0, height, th):
        for tx in range(0, side, tw):
            for y in range(ty, min(ty + th, height)):
                order.extend(range(y * side + tx, y * side + min(tx + tw, side)))
    return np.array(order, dtype=np.int64)


def embreex_check(tris, rays, robust, t_loop, repeats):
    """Traces `rays` with embreex's own loop (same flags, medium quality): returns its median
    Mrays/s and the number of rays whose hit distance differs from `t_loop` bit for bit."""
    scene = rtcs.EmbreeScene(robust=robust)
    TriangleMesh(scene, tris)
    origins = np.ascontiguousarray(rays[:, :3])
    dirs = np.ascontiguousarray(rays[:, 3:])
    scene.run(origins, dirs, output=1)  # warm-up
    rates = []
    for _ in range(repeats):
        t = time.thread_time()
        res = scene.run(origins, dirs, output=1)
        rates.append(len(origins) / (time.thread_time() - t) / 1e6)
    t_ex = np.where(res["geomID"] != -1, res["tfar"], np.inf).astype(np.float32)
    return statistics.median(rates), int((t_ex.view(np.uint32) != t_loop.view(np.uint32)).sum())


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


# Embree's packet variants (--embree-packets): name -> ray order of the 500x500 image.
PACKET_ORDERS = {
    "embree8-rows": lambda side: np.arange(side * side),
    "embree8-4x2": lambda side: tile_order(side, side, 4, 2),
}


def anchor_mesh(mesh, kinds, rounds, repeats, loop, quality, robust, packets=False):
    """Times Embree (through `loop`, an EmbreeLoop) and each marchmesh tracer on MESH's camera
    rays in `rounds` interleaved rounds; prints the table and returns the mesh's record."""
    with tempfile.TemporaryDirectory() as d:
        print(run_example("export", mesh, d).strip(), file=sys.stderr)
        tris = np.fromfile(os.path.join(d, "tris.f32"), dtype="<f4").reshape(-1, 3, 3)
        rays = np.fromfile(os.path.join(d, "rays.f32"), dtype="<f4").reshape(-1, 6)
    tris = np.ascontiguousarray(tris)
    rays = np.ascontiguousarray(rays)
    scene = loop.build(tris, QUALITY[quality], ROBUST_FLAG if robust else 0)
    try:
        _, _, t_loop = loop.trace(scene, rays, 1)
        embreex_rate, mismatches = embreex_check(tris, rays, robust, t_loop, repeats)
        print(
            f"check: embreex's own loop {embreex_rate:.2f} Mrays/s, "
            f"{mismatches} hit distances differ from the C loop's",
            file=sys.stderr,
        )
        if mismatches and quality == "medium":
            sys.exit(
                "anchor_embree: the C loop and embreex disagree on the same build: "
                "scripts/embree_trace.c does not match this libembree4"
            )
        variants = {}
        if packets:
            side = int(round(len(rays) ** 0.5))
            for name, order in PACKET_ORDERS.items():
                idx = order(side)
                ordered = np.ascontiguousarray(rays[idx])
                _, _, t8 = loop.trace(scene, ordered, 1, packets=True)
                differ = int((t8.view(np.uint32) != t_loop[idx].view(np.uint32)).sum())
                print(f"check: {name}: {differ} hit distances differ from rtcIntersect1's",
                      file=sys.stderr)
                variants[name] = ordered
        per = {"embree": [], **{k: [] for k in variants}, **{k: [] for k in kinds}}
        hits = {}
        for r in range(rounds):
            e, hits["embree"], _ = loop.trace(scene, rays, repeats)
            per["embree"].append(e)
            line = f"round {r}: embree {e:.2f} ({hits['embree']} hits)"
            for name, ordered in variants.items():
                m, hits[name], _ = loop.trace(scene, ordered, repeats, packets=True)
                per[name].append(m)
                line += f"  {name} {m:.2f}"
            for k in kinds:
                name, _, build = k.partition("@")
                lines = run_example("time", mesh, name, str(repeats), *([build] if build else []))
                lines = lines.split()
                m = statistics.median(float(x) for x in lines[0::2])
                per[k].append(m)
                hits[k] = int(lines[1])
                line += f"  {k} {m:.2f} ({lines[1]} hits)"
            print(line, file=sys.stderr)
    finally:
        loop.release(scene)
    emb = statistics.median(per["embree"])
    print(f"mesh: {mesh}  triangles: {len(tris)}  rays: {len(rays)}  threads: 1")
    print(f"{'tracer':<14} {'Mrays/s':>8} {'x Embree':>9}")
    print(f"{'embree':<14} {emb:>8.2f} {1.0:>9.3f}")
    record = {
        # Relative to the repository when inside it, else absolute (e.g. the full dragon).
        "mesh": (
            rel
            if not (rel := os.path.relpath(os.path.abspath(mesh), ROOT)).startswith("..")
            else os.path.abspath(mesh)
        ),
        "triangles": len(tris),
        "rays": len(rays),
        "embree": {"mrays_per_s_rounds": per["embree"], "mrays_per_s_median": emb},
        "embree_hits": hits["embree"],
        "embreex_loop_mrays_per_s": embreex_rate,
        "embreex_hit_distance_mismatches": mismatches,
        "tracers": {},
    }
    if variants:
        # Embree's own packets (not marchmesh tracers: `marchmesh findings` reads "tracers").
        record["embree_packets"] = {}
    for k in [*variants, *kinds]:
        ratios = [m / e for m, e in zip(per[k], per["embree"])]
        ratio = statistics.median(ratios)
        print(f"{k:<14} {statistics.median(per[k]):>8.2f} {ratio:>9.3f}")
        record["embree_packets" if k in variants else "tracers"][k] = {
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
        "(4x2-tile packets), wide8 (row batches, no packets), raw (obvhs Bvh2); a suffix "
        "@PRESET builds with that build preset (e.g. wide4x2@medium; default tuned, as renders)",
    )
    ap.add_argument(
        "--embree-quality",
        choices=sorted(QUALITY),
        default="medium",
        help="Embree's build quality (rtcSetSceneBuildQuality; medium is Embree's default, "
        "high adds spatial splits)",
    )
    ap.add_argument(
        "--embree-packets",
        action="store_true",
        help="also time Embree's 8-ray packets (rtcIntersect8) on rows of 8 pixels and on "
        "4x2-pixel tiles (embree8-rows, embree8-4x2), against its single rays",
    )
    ap.add_argument(
        "--embree-robust",
        action="store_true",
        help="set RTC_SCENE_FLAG_ROBUST (embreex's default, not Embree's; slower)",
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
    with tempfile.TemporaryDirectory() as workdir:
        loop = EmbreeLoop(workdir)
        meshes = [
            anchor_mesh(
                m, kinds, a.rounds, a.repeats, loop, a.embree_quality, a.embree_robust,
                a.embree_packets,
            )
            for m in a.mesh
        ]
    load_end = load_average()
    print("load average:", load_end)
    if a.json:
        try:
            wheel = "embreex " + importlib.metadata.version("embreex")
        except importlib.metadata.PackageNotFoundError:
            wheel = "embreex (version unknown)"
        # The label `marchmesh findings` shows: what was timed, not only the wheel.
        embree_version = f"Embree 4 rtcIntersect1 from C ({wheel} library)"
        record = {
            "tool": "anchor-embree",
            "embree_version": embree_version,
            "embree_loop": "rtcIntersect1 in a C loop (scripts/embree_trace.c)",
            "embree_build_quality": a.embree_quality,
            "embree_robust": a.embree_robust,
            "unix_time": int(start),
            "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(start)),
            "cpu": cpu_model(),
            "git_commit": git_commit(),
            "load_average_start": load_start,
            "load_average_end": load_end,
            "threads": 1,
            "rounds": a.rounds,
            "repeats": a.repeats,
            "protocol": "per mesh and round: Embree rtcIntersect1 in a C loop (1 warm-up, "
            "REPEATS timed, median), then each marchmesh tracer in a fresh anchor_rays process (build, 1 "
            "warm-up, REPEATS timed, median); thread CPU time on both sides; ratios are "
            "medians of per-round ratios",
            "meshes": meshes,
        }
        with open(a.json, "x") as f:
            json.dump(record, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
