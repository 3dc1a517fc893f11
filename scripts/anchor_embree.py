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

Incoherent rays (issue 42; off with --no-incoherent): from the camera rays' primary hits
(Embree's, with their triangles) scripts/anchor_incoherent.py draws seeded ambient-occlusion
rays (cosine-weighted about the geometric normal, tmax = --ao-distance times the mesh's
bounding-box diagonal), timed as occlusion queries, and diffuse bounce rays (cosine-weighted,
unbounded), timed as closest-hit queries, and area-light shadow rays (towards a seeded point
on a square light above the mesh, tmax just short of it; only where the light is in front of
the surface), timed as occlusion queries. The same arrays go to Embree (rtcOccluded1 /
rtcIntersect1 per ray, and rtcOccluded8 / rtcIntersect8 on 8 consecutive rays) and to the
mesh backend (`anchor_rays time-rays`: `Geometry::occluded_many` / `closest_hits`, the calls
the integrators make for those rays, in batches of one tile's worth), in the same rounds,
the order reversed on odd rounds. Both sides' answers are compared once per mesh: occlusion
booleans, hit or miss, and hit distances within a relative 1e-4; the disagreements are
printed and recorded, and more than 0.1% of the rays disagreeing stops the script. The JSON
keeps every camera-ray field and adds an "incoherent" object per mesh. --in-box also anchors
each mesh inside an open box (anchor_incoherent.boxed_obj), a Cornell-box-like room where
bounce rays meet walls; its record names the mesh it encloses ("in_box_of").
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import anchor_incoherent  # noqa: E402  (the folder of this script, added above)

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
        lib.anchor_trace_rays.restype = ctypes.c_long
        lib.anchor_trace_rays.argtypes = [
            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
            ctypes.POINTER(ctypes.c_double), ctypes.c_void_p,
        ]
        lib.anchor_primary_hits.restype = ctypes.c_long
        lib.anchor_primary_hits.argtypes = [
            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p,
        ]
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

    # anchor_trace_rays' queries: (occlusion, 8-wide) -> the C loop's code.
    QUERIES = {(False, False): 0, (True, False): 1, (False, True): 2, (True, True): 3}

    def trace_rays(self, scene, rays, occlusion, repeats, packets=False):
        """(median Mrays/s, hits or occluded rays, answers) of `rays` (n x 7 float32: origin,
        direction, tmax): rtcIntersect1 or, with `occlusion`, rtcOccluded1 per ray, or with
        `packets` the 8-wide call per 8 consecutive rays. The answers are hit distances
        (+inf on a miss), or 1 / 0 for occluded / not."""
        rates = (ctypes.c_double * repeats)()
        t = np.empty(len(rays), dtype=np.float32)
        query = self.QUERIES[(occlusion, packets)]
        n = self.lib.anchor_trace_rays(scene, rays.ctypes.data, len(rays), query, repeats,
                                       rates, t.ctypes.data)
        if n < 0:
            sys.exit(f"anchor_embree: the C loop refused query {query}")
        return statistics.median(rates), int(n), t

    def primary_hits(self, scene, rays):
        """(hit distances, hit triangles) of the camera rays `rays` (n x 6 float32), one
        untimed rtcIntersect1 each (+inf and 0xffffffff on a miss)."""
        t = np.empty(len(rays), dtype=np.float32)
        prim = np.empty(len(rays), dtype=np.uint32)
        self.lib.anchor_primary_hits(scene, rays.ctypes.data, len(rays), t.ctypes.data,
                                     prim.ctypes.data)
        return t, prim

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


def repo_path(path):
    """`path` relative to the repository when inside it, else absolute (e.g. the full
    dragon)."""
    rel = os.path.relpath(os.path.abspath(path), ROOT)
    return os.path.abspath(path) if rel.startswith("..") else rel


# Embree's packet variants (--embree-packets): name -> ray order of the 500x500 image.
PACKET_ORDERS = {
    "embree8-rows": lambda side: np.arange(side * side),
    "embree8-4x2": lambda side: tile_order(side, side, 4, 2),
}


# The incoherent ray kinds: name -> (query, timed as an occlusion query).
INCOHERENT_KINDS = {
    "ao": ("occlusion", True),
    "bounce": ("closest hit", False),
    "shadow": ("occlusion", True),
}
# Relative hit-distance difference beyond which two closest hits disagree.
T_TOLERANCE = 1e-4
# Largest share of disagreeing rays accepted before the anchor stops.
MAX_DISAGREEMENT = 1e-3


def disagreements(ours, theirs, occlusion):
    """How many answers differ: occlusion booleans, or hit versus miss and hit distances
    beyond a relative T_TOLERANCE."""
    if occlusion:
        return int(((ours > 0.5) != (theirs > 0.5)).sum())
    hit_a, hit_b = np.isfinite(ours), np.isfinite(theirs)
    both = hit_a & hit_b
    far = np.abs(ours[both].astype(np.float64) - theirs[both]) > T_TOLERANCE * np.maximum(
        1.0, np.abs(theirs[both].astype(np.float64))
    )
    return int((hit_a != hit_b).sum() + far.sum())


def incoherent_sets(tris, camera_rays, scene, loop, options, boxed=False):
    """The incoherent rays drawn from the camera rays' hits on `scene` (Embree's, through
    `loop`; see anchor_incoherent.py) with the parsed `options` (seed, per_hit,
    ao_distance): ({kind: rays}, the start of the mesh's "incoherent" record, its "kinds"
    still empty). `boxed`: the mesh is a boxed_obj room, whose area light hangs under the
    ceiling. scripts/anchor_tinybvh.py draws its rays here too, so both anchors time the
    same rays."""
    t_hit, prim = loop.primary_hits(scene, camera_rays)
    lo = tris.reshape(-1, 3).min(axis=0).astype(np.float64)
    hi = tris.reshape(-1, 3).max(axis=0).astype(np.float64)
    diagonal = float(np.linalg.norm(hi - lo))
    ao_distance = options.ao_distance * diagonal
    # Over a lone mesh; under the ceiling of a boxed one (the ceiling would shadow it all).
    light_height = -0.005 if boxed else 0.5
    light = anchor_incoherent.light_above(lo, hi, height=light_height)
    sets = anchor_incoherent.incoherent_rays(
        camera_rays, t_hit, prim, tris, options.seed, ao_distance, options.per_hit, light=light
    )
    record = {
        "seed": options.seed,
        "rays_per_hit": options.per_hit,
        "camera_hits": int(np.isfinite(t_hit).sum()),
        "ray_offset": anchor_incoherent.RAY_OFFSET,
        "ao_distance": ao_distance,
        "ao_distance_over_bounds_diagonal": options.ao_distance,
        "area_light": {
            "corner": light[0].tolist(),
            "edge_u": light[1].tolist(),
            "edge_v": light[2].tolist(),
            "placement": "a square of 0.25 bounding-box diagonals, centred over the box, "
            f"{light_height} diagonals above its top, emitting downwards "
            "(anchor_incoherent.light_above)",
        },
        "hit_distance_tolerance_relative": T_TOLERANCE,
        "kinds": {},
    }
    return sets, record


def time_incoherent(mesh, tris, camera_rays, scene, loop, tracers, rounds, repeats, options,
                    workdir, boxed=False):
    """Times Embree and the mesh backend's `tracers` on the incoherent rays drawn from the
    camera rays' hits on `scene` (see anchor_incoherent.py) in `rounds` interleaved rounds,
    the order reversed on odd rounds; returns the mesh's "incoherent" record. `boxed`: the
    mesh is a boxed_obj room, whose area light hangs under the ceiling."""
    sets, record = incoherent_sets(tris, camera_rays, scene, loop, options, boxed)
    for kind, rays in sets.items():
        query, occlusion = INCOHERENT_KINDS[kind]
        path = os.path.join(workdir, f"{kind}.f32")
        rays.astype("<f4").tofile(path)
        _, _, answers = loop.trace_rays(scene, rays, occlusion, 1)
        _, _, answers8 = loop.trace_rays(scene, rays, occlusion, 1, packets=True)
        embree8_differ = disagreements(answers8, answers, occlusion)
        sides = ["embree1", "embree8", *tracers]
        per = {k: [] for k in sides}
        found = {}
        differ = {"embree8": embree8_differ}
        for r in range(rounds):
            for side in sides if r % 2 == 0 else sides[::-1]:
                if side.startswith("embree"):
                    m, found[side], _ = loop.trace_rays(
                        scene, rays, occlusion, repeats, packets=side == "embree8"
                    )
                else:
                    name, _, build = side.partition("@")
                    out_path = os.path.join(workdir, f"{kind}-{name}.out")
                    lines = run_example(
                        "time-rays", mesh, name, "occluded" if occlusion else "closest", path,
                        str(repeats), out_path, *([build] if build else []),
                    ).split()
                    m = statistics.median(float(x) for x in lines[0::2])
                    found[side] = int(lines[1])
                    if side not in differ:
                        ours = np.fromfile(out_path, dtype="<f4")
                        differ[side] = disagreements(ours, answers, occlusion)
                per[side].append(m)
            print(
                f"round {r}: {kind} "
                + "  ".join(f"{k} {per[k][-1]:.2f} ({found[k]})" for k in sides),
                file=sys.stderr,
            )
        for side, n in differ.items():
            if n > MAX_DISAGREEMENT * len(rays):
                sys.exit(
                    f"anchor_embree: {mesh}: {kind} rays: {side} disagrees with Embree's "
                    f"single-ray answers on {n} of {len(rays)} rays"
                )
        emb = statistics.median(per["embree1"])
        entry = {
            "query": query,
            "rays": len(rays),
            "tmax": (
                "per ray (just short of the light)" if kind == "shadow"
                else "inf" if not np.isfinite(rays[0, 6]) else float(rays[0, 6])
            ),
            "embree": {
                "call": "rtcOccluded1" if occlusion else "rtcIntersect1",
                "mrays_per_s_rounds": per["embree1"],
                "mrays_per_s_median": emb,
                "hits": found["embree1"],
            },
            "embree8": {
                "call": "rtcOccluded8" if occlusion else "rtcIntersect8",
                "mrays_per_s_rounds": per["embree8"],
                "mrays_per_s_median": statistics.median(per["embree8"]),
                "ratio_over_embree_per_round_median": statistics.median(
                    m / e for m, e in zip(per["embree8"], per["embree1"])
                ),
                "hits": found["embree8"],
                "disagreements": differ["embree8"],
            },
            "tracers": {},
        }
        for side in tracers:
            entry["tracers"][side] = {
                "mrays_per_s_rounds": per[side],
                "mrays_per_s_median": statistics.median(per[side]),
                "ratio_over_embree_per_round_median": statistics.median(
                    m / e for m, e in zip(per[side], per["embree1"])
                ),
                "hits": found[side],
                "disagreements": differ[side],
            }
        record["kinds"][kind] = entry
    return record


def print_incoherent(record):
    """The incoherent rays' table of one mesh (its record from time_incoherent): per ray kind,
    Embree's single-ray call, its 8-wide call and each marchmesh tracer, with the ratio to the
    single-ray call, the rays hit or occluded, and the rays whose answer differs from it."""
    print(
        f"incoherent rays from {record['camera_hits']} camera hits, {record['rays_per_hit']} "
        f"per hit, seed {record['seed']}, AO distance {record['ao_distance']:.4g}"
    )
    print(
        f"{'rays':<7} {'query':<12} {'tracer':<14} {'Mrays/s':>8} {'x Embree':>9} "
        f"{'hits':>7} {'differ':>6}"
    )
    for kind, e in record["kinds"].items():
        rows = [("embree", {**e["embree"], "ratio_over_embree_per_round_median": 1.0,
                            "disagreements": 0}),
                ("embree8", e["embree8"]),
                *e["tracers"].items()]
        for name, t in rows:
            print(
                f"{kind:<7} {e['query']:<12} {name:<14} {t['mrays_per_s_median']:>8.2f} "
                f"{t['ratio_over_embree_per_round_median']:>9.3f} {t['hits']:>7} "
                f"{t['disagreements']:>6}"
            )


def anchor_mesh(mesh, kinds, rounds, repeats, loop, quality, robust, packets=False,
                incoherent=None, boxed=False):
    """Times Embree (through `loop`, an EmbreeLoop) and each marchmesh tracer on MESH's camera
    rays in `rounds` interleaved rounds, then (unless `incoherent`, the parsed options, is
    None) on the incoherent rays; prints the tables and returns the mesh's record."""
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
        inc = None
        if incoherent is not None:
            with tempfile.TemporaryDirectory() as d:
                inc = time_incoherent(
                    mesh, tris, rays, scene, loop, incoherent.incoherent_bvh.split(","), rounds,
                    repeats, incoherent, d, boxed,
                )
    finally:
        loop.release(scene)
    emb = statistics.median(per["embree"])
    print(f"mesh: {mesh}  triangles: {len(tris)}  rays: {len(rays)}  threads: 1")
    print(f"{'tracer':<14} {'Mrays/s':>8} {'x Embree':>9}")
    print(f"{'embree':<14} {emb:>8.2f} {1.0:>9.3f}")
    record = {
        "mesh": repo_path(mesh),
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
    if inc is not None:
        print_incoherent(inc)
        record["incoherent"] = inc
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
    ap.add_argument(
        "--no-incoherent",
        action="store_true",
        help="camera rays only (skip the ambient-occlusion and bounce rays)",
    )
    ap.add_argument(
        "--incoherent-bvh",
        default="wide",
        help="marchmesh tracers for the incoherent rays (bvh2, cwbvh, wide; @PRESET as for "
        "--bvh): each traces them through the backend's batch calls, as renders do",
    )
    ap.add_argument(
        "--in-box",
        action="store_true",
        help="also anchor each mesh inside an open box (floor, ceiling, back and side walls, "
        "open towards the camera: anchor_incoherent.boxed_obj), where bounce rays meet walls; OBJ "
        "meshes only",
    )
    ap.add_argument("--seed", type=int, default=42, help="seed of the incoherent rays")
    ap.add_argument(
        "--per-hit",
        type=int,
        default=1,
        help="incoherent rays of each kind per camera hit",
    )
    ap.add_argument(
        "--ao-distance",
        type=float,
        default=0.1,
        help="the AO rays' tmax as a fraction of the mesh's bounding-box diagonal",
    )
    a = ap.parse_args()
    if a.in_box and any(not m.lower().endswith(".obj") for m in a.mesh):
        ap.error("--in-box: OBJ meshes only")
    if a.per_hit < 1 or not a.ao_distance > 0:
        ap.error("--per-hit must be at least 1 and --ao-distance positive")
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
        subjects = [(m, None) for m in a.mesh]
        if a.in_box:
            for k, m in enumerate(a.mesh):
                boxed = os.path.join(workdir, f"{k}-{os.path.basename(m)}")
                anchor_incoherent.boxed_obj(m, boxed)
                subjects.append((boxed, m))
        meshes = []
        for m, box_of in subjects:
            record = anchor_mesh(
                m, kinds, a.rounds, a.repeats, loop, a.embree_quality, a.embree_robust,
                a.embree_packets, None if a.no_incoherent else a, box_of is not None,
            )
            if box_of is not None:
                # Named after the mesh it encloses (the file itself is temporary).
                record["mesh"] = f"{repo_path(box_of)} in an open box"
                record["in_box_of"] = repo_path(box_of)
            meshes.append(record)
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
            "incoherent_protocol": None if a.no_incoherent else "per mesh: AO rays "
            "(occlusion queries, tmax = ao_distance) and diffuse bounce rays (closest hit, "
            "unbounded), cosine-weighted about the geometric normal of each camera ray's "
            "Embree hit, and shadow rays towards a uniform point on area_light (occlusion, "
            "tmax just short of it, none where the light is behind the surface), origin "
            "offset by ray_offset x distance from the camera "
            "(scripts/anchor_incoherent.py); per round (order reversed on odd rounds): Embree "
            "rtcOccluded1/rtcIntersect1 per ray and rtcOccluded8/rtcIntersect8 on 8 "
            "consecutive rays in a C loop, and each marchmesh tracer in a fresh anchor_rays "
            "time-rays process (Geometry::occluded_many / closest_hits in batches of 512 "
            "rays); 1 warm-up, REPEATS timed, median; thread CPU time; ratios are medians of "
            "per-round ratios over rtcOccluded1/rtcIntersect1; hits counts the rays hit "
            "(closest hit) or occluded (occlusion); disagreements counts the rays whose answer "
            "differs from Embree's single-ray one (occlusion boolean, hit or miss, or hit "
            "distance beyond the relative tolerance)",
            "meshes": meshes,
        }
        with open(a.json, "x") as f:
            json.dump(record, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
