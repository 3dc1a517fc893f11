#!/usr/bin/env python3
"""tinybvh anchor for the mesh backend, beside Embree: times tinybvh's single-ray traversal
(Jacco Bikker's header-only C++ library, github.com/jbikker/tinybvh, MIT), Embree 4 and the
mesh backend on the same camera and incoherent rays of each mesh, interleaved, 1 thread.

Setup:  the Embree anchor's environment (embreex and numpy: see scripts/anchor_embree.py), a
        C++ compiler (`c++`, or $CXX) and tinybvh's tiny_bvh.h, found at run time, never
        vendored here: $TINYBVH_DIR/tiny_bvh.h (a checkout or an unpacked release), else
        `git show HEAD:tiny_bvh.h` of the git directory $TINYBVH_GIT_DIR (default
        /work/.mirror/jbikker+tinybvh/repo, where the development machines keep a mirror);
        the script stops naming both when neither has the header.
Run:    EMBREE_PYTHON scripts/anchor_tinybvh.py MESH.obj [MESH...] [--rounds 7] [--repeats 9]
            [--layouts bvh8,bvh4,bvh8-hq] [--in-box] [--json OUT.json]
(scripts/anchor_tinybvh.sh runs it on the three meshes of the Embree anchor and writes
bench-results/anchors/tinybvh-<UTC stamp>.{json,md}.)

Per mesh: `anchor_rays export` writes the camera rays and render-space triangles (the same
files the Embree anchor traces); Embree's primary hits give the incoherent rays exactly as
scripts/anchor_embree.py draws them (anchor_embree.incoherent_sets: AO, bounce and area-light
shadow rays, same seed and options). Then per ray kind, in ROUNDS rounds (order reversed on
odd rounds), each side traces the same rays (1 warm-up, REPEATS timed, median):

- Embree 4 (scripts/embree_trace.c in this process): rtcIntersect1 / rtcOccluded1 per ray
  ("embree1"), and rtcIntersect8 / rtcOccluded8 ("embree8") on 4x2-pixel tiles of camera rays
  or on 8 consecutive incoherent rays;
- tinybvh (scripts/tinybvh_trace.cpp, compiled here with -O3 -march=native, a fresh process
  per round that builds its BVH, timed): Intersect / IsOccluded per ray on each LAYOUT
  (`bvh8` BVH8_CPU, `bvh4` BVH4_CPU, `soa` BVH_SoA, `bvh` BVH; `-hq` builds with BuildHQ);
- the mesh backend (`anchor_rays`, a fresh process per round): camera rays as `wide1` (single
  rays) and `wide4x2` (8-ray packets on 4x2 tiles); incoherent rays as `wide` through
  `Geometry::occluded_many` / `closest_hits` in batches of 512 rays (`time-rays`).

Thread CPU time on every side (CLOCK_THREAD_CPUTIME_ID), so time spent descheduled on a
loaded machine counts on no side. Ratios are medians of per-round ratios; "faster
single-ray peer" is, per round, the faster of Embree's single-ray call and tinybvh's layouts
(the issue's target: the mesh backend at least 1.0x it), "fastest peer" the fastest of all
their calls on those rays, Embree's 8-wide ones included.

Agreement: every tinybvh layout's answers, Embree's 8-wide answers and the mesh backend's
incoherent answers are compared with Embree's single-ray answers: occlusion booleans, hit or
miss, hit distances within a relative 1e-4 (anchor_embree.T_TOLERANCE); the counts are
printed and recorded, and more than 0.1% of the rays disagreeing stops the script. (The mesh
backend's camera-ray mode reports hit counts only; those are recorded beside Embree's.)
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
# Where the development machines keep a git mirror of github.com/jbikker/tinybvh.
DEFAULT_GIT_DIR = "/work/.mirror/jbikker+tinybvh/repo"
HEADER = "tiny_bvh.h"
CXX_FLAGS = ["-O3", "-march=native", "-std=c++17", "-pthread"]
LAYOUTS = {
    "bvh8": "BVH8_CPU",
    "bvh4": "BVH4_CPU",
    "soa": "BVH_SoA",
    "bvh": "BVH",
}
# Ray kinds: name -> (query of tinybvh_trace, occlusion query?).
KINDS = {
    "camera": ("camera", False),
    "ao": ("occluded", True),
    "bounce": ("closest", False),
    "shadow": ("occluded", True),
}


class SetupError(Exception):
    """Something the anchor needs is missing; the message says what and where to put it."""


def find_header(workdir, environ=None, git="git"):
    """Locates tiny_bvh.h: (path, where it came from, git commit or None). $TINYBVH_DIR must
    hold tiny_bvh.h when set; otherwise the header is read from HEAD of the git directory
    $TINYBVH_GIT_DIR (default DEFAULT_GIT_DIR) into `workdir`. Raises SetupError naming
    what is missing."""
    env = os.environ if environ is None else environ
    d = env.get("TINYBVH_DIR")
    if d:
        path = os.path.join(d, HEADER)
        if not os.path.isfile(path):
            raise SetupError(f"TINYBVH_DIR={d}: no {HEADER} there")
        return path, path, None
    git_dir = env.get("TINYBVH_GIT_DIR") or DEFAULT_GIT_DIR
    if not os.path.isdir(git_dir):
        raise SetupError(
            f"no tinybvh header: TINYBVH_DIR is unset and {git_dir} (TINYBVH_GIT_DIR) is not a "
            f"git directory; set TINYBVH_DIR to a folder holding {HEADER} from "
            "https://github.com/jbikker/tinybvh"
        )
    try:
        text = subprocess.run(
            [git, f"--git-dir={git_dir}", "show", f"HEAD:{HEADER}"],
            check=True, capture_output=True,
        ).stdout
        commit = subprocess.run(
            [git, f"--git-dir={git_dir}", "rev-parse", "HEAD"],
            check=True, capture_output=True, text=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError) as e:
        raise SetupError(f"{git_dir}: cannot read HEAD:{HEADER} ({e}); set TINYBVH_DIR") from e
    path = os.path.join(workdir, HEADER)
    with open(path, "wb") as f:
        f.write(text)
    return path, f"{git_dir} (HEAD:{HEADER})", commit


def header_version(text):
    """tinybvh's version ("1.6.7") from its header's TINY_BVH_VERSION_* defines, or None."""
    parts = []
    for name in ("MAJOR", "MINOR", "SUB"):
        m = re.search(rf"^\s*#define\s+TINY_BVH_VERSION_{name}\s+(\d+)\b", text, re.M)
        if not m:
            return None
        parts.append(m.group(1))
    return ".".join(parts)


def parse_trace_output(text):
    """tinybvh_trace's standard output: a `build WALL_S CPU_S BYTES` line, then one
    `Mrays/s count` line per timed pass. Returns {"build_wall_s", "build_cpu_s", "bytes",
    "rates", "count"} (count: the last pass's); raises ValueError on anything else."""
    lines = [line.split() for line in text.splitlines() if line.strip()]
    if not lines or lines[0][:1] != ["build"] or len(lines[0]) != 4:
        raise ValueError(f"tinybvh_trace: no build line first: {text[:200]!r}")
    wall, cpu, size = float(lines[0][1]), float(lines[0][2]), int(lines[0][3])
    if len(lines) < 2:
        raise ValueError("tinybvh_trace: no timed passes")
    rates, counts = [], []
    for fields in lines[1:]:
        if len(fields) != 2:
            raise ValueError(f"tinybvh_trace: not `Mrays/s count`: {' '.join(fields)!r}")
        rate, count = float(fields[0]), int(fields[1])
        if not (rate > 0 and rate != float("inf")) or count < 0:
            raise ValueError(f"tinybvh_trace: bad pass {' '.join(fields)!r}")
        rates.append(rate)
        counts.append(count)
    if len(set(counts)) != 1:
        raise ValueError(f"tinybvh_trace: passes found different counts {sorted(set(counts))}")
    return {"build_wall_s": wall, "build_cpu_s": cpu, "bytes": size, "rates": rates,
            "count": counts[-1]}


def parse_pairs(text):
    """`anchor_rays time` / `time-rays` output, `Mrays/s count` per pass: (rates, count)."""
    fields = text.split()
    if not fields or len(fields) % 2:
        raise ValueError(f"anchor_rays: not `Mrays/s count` pairs: {text[:200]!r}")
    return [float(x) for x in fields[0::2]], int(fields[1])


def round_order(sides, r):
    """The sides in round `r`'s order: as given on even rounds, reversed on odd ones."""
    return list(sides) if r % 2 == 0 else list(sides)[::-1]


def ratio(ours, theirs):
    """The median of per-round ratios ours[r] / theirs[r]."""
    if len(ours) != len(theirs) or not ours:
        raise ValueError("ratio: rounds differ")
    return statistics.median(o / t for o, t in zip(ours, theirs))


def ratio_to_fastest(ours, peers):
    """The median over rounds of ours[r] / (the fastest of `peers`' rates in round r)
    (`peers`: name -> per-round rates), and how many rounds each peer was the fastest."""
    if not peers:
        raise ValueError("ratio_to_fastest: no peers")
    names = sorted(peers)
    wins = {n: 0 for n in names}
    ratios = []
    for r, o in enumerate(ours):
        best = max(names, key=lambda n: peers[n][r])
        wins[best] += 1
        ratios.append(o / peers[best][r])
    return statistics.median(ratios), wins


def mesh_tracers(kind):
    """The mesh backend's tracers on a kind of rays."""
    return ["wide1", "wide4x2"] if kind == "camera" else ["wide"]


def compile_trace(workdir, header):
    """Compiles scripts/tinybvh_trace.cpp against `header` into `workdir`: the program's path
    and the command."""
    exe = os.path.join(workdir, "tinybvh_trace")
    src = os.path.join(HERE, "tinybvh_trace.cpp")
    cxx = os.environ.get("CXX", "c++")
    cmd = [cxx, *CXX_FLAGS, "-I", os.path.dirname(header), "-o", exe, src]
    try:
        subprocess.run(cmd, check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        raise SetupError(f"compiling {src} with `{cxx}` failed ({e}); set CXX") from e
    return exe, " ".join([os.path.basename(cxx), *CXX_FLAGS, "scripts/tinybvh_trace.cpp"])


def anchor_mesh(mesh, exe, loop, layouts, rounds, repeats, options, boxed=False):
    """Times Embree, tinybvh's `layouts` and the mesh backend on MESH's camera and incoherent
    rays; prints the tables and returns the mesh's record."""
    import tempfile

    import numpy as np

    import anchor_embree as ae

    with tempfile.TemporaryDirectory() as d:
        print(ae.run_example("export", mesh, d).strip(), file=sys.stderr)
        tris_path = os.path.join(d, "tris.f32")
        tris = np.ascontiguousarray(np.fromfile(tris_path, dtype="<f4").reshape(-1, 3, 3))
        camera = np.ascontiguousarray(
            np.fromfile(os.path.join(d, "rays.f32"), dtype="<f4").reshape(-1, 6)
        )
        t0 = time.monotonic()
        scene = loop.build(tris, ae.QUALITY["medium"], 0)
        embree_build = time.monotonic() - t0
        try:
            sets, inc = ae.incoherent_sets(tris, camera, scene, loop, options, boxed)
            sets = {"camera": camera, **sets}
            record = {
                "mesh": ae.repo_path(mesh),
                "triangles": len(tris),
                "embree_build_wall_s": embree_build,
                "incoherent": {k: v for k, v in inc.items() if k != "kinds"},
                "tinybvh_builds": {},
                "kinds": {},
            }
            builds = {layout: [] for layout in layouts}
            for kind, rays in sets.items():
                record["kinds"][kind] = time_kind(
                    mesh, kind, rays, d, tris_path, exe, scene, loop, layouts, rounds,
                    repeats, builds,
                )
            for layout, b in builds.items():
                record["tinybvh_builds"][layout] = {
                    "class": LAYOUTS[layout.removesuffix("-hq")],
                    "builder": "BuildHQ" if layout.endswith("-hq") else "Build",
                    "bytes": b[0]["bytes"],
                    "wall_s_median": statistics.median(x["build_wall_s"] for x in b),
                    "process_cpu_s_median": statistics.median(x["build_cpu_s"] for x in b),
                    "builds": len(b),
                }
        finally:
            loop.release(scene)
    print_mesh(record)
    return record


def time_kind(mesh, kind, rays, workdir, tris_path, exe, scene, loop, layouts, rounds, repeats,
              builds):
    """One kind of rays of one mesh: every side in `rounds` interleaved rounds; returns the
    kind's record (and appends each tinybvh build to `builds`)."""
    import numpy as np

    import anchor_embree as ae

    query, occlusion = KINDS[kind]
    camera = kind == "camera"
    path = os.path.join(workdir, "rays.f32" if camera else f"{kind}.f32")
    if not camera:
        rays.astype("<f4").tofile(path)
    # Embree's single-ray answers are the reference; its 8-wide call traces 4x2 tiles of
    # camera rays (the mesh backend's wide4x2 order) or 8 consecutive incoherent rays.
    if camera:
        _, _, reference = loop.trace(scene, rays, 1)
        side = int(round(len(rays) ** 0.5))
        order = ae.tile_order(side, len(rays) // side, 4, 2)
        tiled = np.ascontiguousarray(rays[order])
        _, _, t8 = loop.trace(scene, tiled, 1, packets=True)
        differ = {"embree8": ae.disagreements(t8, reference[order], False)}
    else:
        _, _, reference = loop.trace_rays(scene, rays, occlusion, 1)
        _, _, t8 = loop.trace_rays(scene, rays, occlusion, 1, packets=True)
        differ = {"embree8": ae.disagreements(t8, reference, occlusion)}
    tracers = mesh_tracers(kind)
    sides = ["embree1", "embree8", *[f"tinybvh-{x}" for x in layouts], *tracers]
    per = {s: [] for s in sides}
    found = {}
    for r in range(rounds):
        for s in round_order(sides, r):
            if s == "embree1":
                if camera:
                    m, n, _ = loop.trace(scene, rays, repeats)
                else:
                    m, n, _ = loop.trace_rays(scene, rays, occlusion, repeats)
            elif s == "embree8":
                if camera:
                    m, n, _ = loop.trace(scene, tiled, repeats, packets=True)
                else:
                    m, n, _ = loop.trace_rays(scene, rays, occlusion, repeats, packets=True)
            elif s.startswith("tinybvh-"):
                layout = s.removeprefix("tinybvh-")
                out = os.path.join(workdir, f"{kind}-{layout}.out")
                res = subprocess.run(
                    [exe, tris_path, layout, query, path, str(repeats), out],
                    check=True, capture_output=True, text=True,
                )
                p = parse_trace_output(res.stdout)
                builds[layout].append(p)
                m, n = statistics.median(p["rates"]), p["count"]
                if s not in differ:
                    differ[s] = ae.disagreements(np.fromfile(out, dtype="<f4"), reference,
                                                 occlusion)
            elif camera:
                rates, n = parse_pairs(ae.run_example("time", mesh, s, str(repeats)))
                m = statistics.median(rates)
            else:
                out = os.path.join(workdir, f"{kind}-{s}.out")
                rates, n = parse_pairs(ae.run_example(
                    "time-rays", mesh, s, "occluded" if occlusion else "closest", path,
                    str(repeats), out,
                ))
                m = statistics.median(rates)
                if s not in differ:
                    differ[s] = ae.disagreements(np.fromfile(out, dtype="<f4"), reference,
                                                 occlusion)
            per[s].append(m)
            found[s] = int(n)
        print(f"round {r}: {kind} " + "  ".join(f"{s} {per[s][-1]:.2f} ({found[s]})"
                                                for s in sides), file=sys.stderr)
    for s, n in differ.items():
        if n > ae.MAX_DISAGREEMENT * len(rays):
            sys.exit(f"anchor_tinybvh: {mesh}: {kind} rays: {s} disagrees with Embree's "
                     f"single-ray answers on {n} of {len(rays)} rays")
    peers = [s for s in sides if s not in tracers]
    entry = {
        "query": "occlusion" if occlusion else "closest hit",
        "rays": len(rays),
        "sides": {},
        "marchmesh": {},
    }
    calls = {
        "embree1": "rtcOccluded1" if occlusion else "rtcIntersect1",
        "embree8": ("rtcOccluded8" if occlusion else "rtcIntersect8")
        + (" on 4x2-pixel tiles" if camera else " on 8 consecutive rays"),
    }
    for s in sides:
        if s.startswith("tinybvh-"):
            layout = s.removeprefix("tinybvh-")
            call = (f"{LAYOUTS[layout.removesuffix('-hq')]}::"
                    + ("IsOccluded" if occlusion else "Intersect"))
        elif s in calls:
            call = calls[s]
        else:
            call = "anchor_rays " + ("time" if camera else "time-rays")
        entry["sides"][s] = {
            "call": call,
            "mrays_per_s_rounds": per[s],
            "mrays_per_s_median": statistics.median(per[s]),
            "ratio_over_embree1_per_round_median": ratio(per[s], per["embree1"]),
            "hits": found[s],
            "disagreements": differ.get(s),
        }
    singles = [p for p in peers if p != "embree8"]
    tinies = [p for p in peers if p.startswith("tinybvh-")]
    for t in tracers:
        to_tiny, _ = ratio_to_fastest(per[t], {p: per[p] for p in tinies})
        to_single, single_wins = ratio_to_fastest(per[t], {p: per[p] for p in singles})
        to_fastest, wins = ratio_to_fastest(per[t], {p: per[p] for p in peers})
        entry["marchmesh"][t] = {
            "over": {p: ratio(per[t], per[p]) for p in peers},
            "over_fastest_tinybvh": to_tiny,
            "over_faster_single_ray_peer": to_single,
            "faster_single_ray_peer_rounds": single_wins,
            "over_fastest_peer": to_fastest,
            "fastest_peer_rounds": wins,
        }
    return entry


def print_mesh(record):
    """The tables of one mesh's record."""
    print(f"mesh: {record['mesh']}  triangles: {record['triangles']}  threads: 1")
    inc = record["incoherent"]
    print(f"incoherent rays from {inc['camera_hits']} camera hits, seed {inc['seed']}, "
          f"AO distance {inc['ao_distance']:.4g}")
    builds = ", ".join(
        f"{k} {b['wall_s_median'] * 1e3:.1f} ms wall / {b['process_cpu_s_median'] * 1e3:.1f} ms "
        f"CPU ({b['bytes'] / 2**20:.2f} MiB)" for k, b in record["tinybvh_builds"].items()
    )
    print(f"builds: Embree {record['embree_build_wall_s'] * 1e3:.1f} ms wall (first build); "
          f"tinybvh {builds}")
    print(f"{'rays':<7} {'query':<12} {'side':<16} {'Mrays/s':>8} {'x embree1':>9} "
          f"{'hits':>7} {'differ':>6}")
    for kind, e in record["kinds"].items():
        for s, t in e["sides"].items():
            d = "-" if t["disagreements"] is None else str(t["disagreements"])
            print(f"{kind:<7} {e['query']:<12} {s:<16} {t['mrays_per_s_median']:>8.2f} "
                  f"{t['ratio_over_embree1_per_round_median']:>9.3f} {t['hits']:>7} {d:>6}")
    print("marchmesh over each peer (medians of per-round ratios):")
    for kind, e in record["kinds"].items():
        for t, m in e["marchmesh"].items():
            over = "  ".join(f"/{p} {v:.3f}" for p, v in m["over"].items())
            print(f"{kind:<7} {t:<8} {over}  /tinybvh-best {m['over_fastest_tinybvh']:.3f}"
                  f"  /faster-single "
                  f"{m['over_faster_single_ray_peer']:.3f}  /fastest {m['over_fastest_peer']:.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mesh", nargs="+", help="OBJ/PLY/glTF meshes, each anchored in turn")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--layouts", default="bvh8,bvh4,bvh8-hq",
                    help="tinybvh layouts: bvh8 (BVH8_CPU), bvh4 (BVH4_CPU), soa (BVH_SoA), "
                    "bvh (BVH); a suffix -hq builds with BuildHQ (spatial splits)")
    ap.add_argument("--in-box", action="store_true",
                    help="also anchor each mesh inside an open box (anchor_incoherent.boxed_obj)")
    ap.add_argument("--seed", type=int, default=42, help="seed of the incoherent rays")
    ap.add_argument("--per-hit", type=int, default=1,
                    help="incoherent rays of each kind per camera hit")
    ap.add_argument("--ao-distance", type=float, default=0.1,
                    help="the AO rays' tmax as a fraction of the mesh's bounding-box diagonal")
    ap.add_argument("--json", metavar="PATH", help="also write every figure as JSON "
                    "(refuses to overwrite a file)")
    a = ap.parse_args()
    layouts = [x for x in a.layouts.split(",") if x]
    bad = [x for x in layouts if x.removesuffix("-hq") not in LAYOUTS]
    if not layouts or bad:
        ap.error(f"--layouts: unknown {bad} (known: {', '.join(LAYOUTS)}, each with -hq)")
    if a.rounds < 1 or a.repeats < 1 or a.per_hit < 1 or not a.ao_distance > 0:
        ap.error("--rounds, --repeats and --per-hit must be at least 1, --ao-distance positive")
    if a.in_box and any(not m.lower().endswith(".obj") for m in a.mesh):
        ap.error("--in-box: OBJ meshes only")
    if a.json and os.path.lexists(a.json):
        ap.error(f"--json {a.json}: exists (nothing was overwritten)")
    import json
    import tempfile

    sys.path.insert(0, HERE)
    import anchor_embree as ae
    import anchor_incoherent

    start = time.time()
    load_start = ae.load_average()
    print("load average at start:", load_start)
    with tempfile.TemporaryDirectory() as workdir:
        try:
            header, source, commit = find_header(workdir)
            with open(header, encoding="utf-8", errors="replace") as f:
                version = header_version(f.read())
            exe, compiled = compile_trace(workdir, header)
        except SetupError as e:
            sys.exit(f"anchor_tinybvh: {e}")
        print(f"tinybvh {version} from {source}", file=sys.stderr)
        loop = ae.EmbreeLoop(workdir)
        subjects = [(m, None) for m in a.mesh]
        if a.in_box:
            for k, m in enumerate(a.mesh):
                boxed = os.path.join(workdir, f"{k}-{os.path.basename(m)}")
                anchor_incoherent.boxed_obj(m, boxed)
                subjects.append((boxed, m))
        meshes = []
        for m, box_of in subjects:
            record = anchor_mesh(m, exe, loop, layouts, a.rounds, a.repeats, a,
                                 box_of is not None)
            if box_of is not None:
                record["mesh"] = f"{ae.repo_path(box_of)} in an open box"
                record["in_box_of"] = ae.repo_path(box_of)
            meshes.append(record)
    load_end = ae.load_average()
    print("load average:", load_end)
    if a.json:
        try:
            import importlib.metadata

            wheel = "embreex " + importlib.metadata.version("embreex")
        except Exception:  # noqa: BLE001  (only a label)
            wheel = "embreex (version unknown)"
        out = {
            "tool": "anchor-tinybvh",
            "tinybvh_version": f"tinybvh {version}",
            "tinybvh_source": source,
            "tinybvh_commit": commit,
            "tinybvh_compiled": compiled,
            "embree_version": f"Embree 4 from C ({wheel} library), default flags, medium "
            "quality",
            "unix_time": int(start),
            "date_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(start)),
            "cpu": ae.cpu_model(),
            "git_commit": ae.git_commit(),
            "load_average_start": load_start,
            "load_average_end": load_end,
            "threads": 1,
            "rounds": a.rounds,
            "repeats": a.repeats,
            "layouts": layouts,
            "hit_distance_tolerance_relative": ae.T_TOLERANCE,
            "protocol": "per mesh and ray kind (camera rays of anchor_rays export; AO, bounce "
            "and shadow rays of anchor_embree.incoherent_sets), per round, order reversed on "
            "odd rounds: Embree rtcIntersect1/rtcOccluded1 per ray and rtcIntersect8/"
            "rtcOccluded8 (4x2 tiles of camera rays, 8 consecutive incoherent rays) in a C "
            "loop; each tinybvh layout in a fresh tinybvh_trace process (build, "
            "Intersect/IsOccluded per ray); the mesh backend in a fresh anchor_rays process "
            "(camera: time wide1, wide4x2; incoherent: time-rays wide); each side 1 warm-up, "
            "REPEATS timed, median; thread CPU time; ratios are medians of per-round ratios; "
            "over_faster_single_ray_peer divides by the faster of Embree's single-ray call and "
            "the tinybvh layouts in the round, over_fastest_tinybvh by the round's fastest "
            "tinybvh layout, over_fastest_peer by the fastest Embree or "
            "tinybvh call of the round (8-wide calls included); "
            "disagreements count rays whose answer differs from Embree's single-ray one "
            "(occlusion boolean, hit or miss, hit distance beyond the relative tolerance; "
            "null where a side writes no answers)",
            "meshes": meshes,
        }
        with open(a.json, "x") as f:
            json.dump(out, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
