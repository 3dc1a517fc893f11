#!/usr/bin/env python3
"""Writes the generated scenes of the `sculpted` suite into scenes/generated/sculpted/.
Deterministic (seeded); rerun after changing it and commit the output. Python 3, stdlib only.

Sculpted content is what signed distance fields are used for in practice: many primitives
joined by smooth blends (molecule-like models, as in Barbier, Sanchez et al. 2025, "Lipschitz
Pruning: Hierarchical Simplification of Primitive-Based SDFs").

Series:
  molecule_<n>.json  n = 10, 100, 1000, 10000 spheres of radius 0.032 in one smooth union
                     (blend radius 0.026): the first n centres of one seeded random walk
                     (steps of 0.04 in uniformly random directions, reflected back into a ball
                     of radius 0.7 so the chain folds into a compact molecule), the camera
                     2.6 units from the centroid of the n centres, looking at it.

  molecule_blend_<n>.json
                     the same n spheres in one blend (`blend`, the same blend radius): the union
                     of all children blended at once, the same value in any order, which the sdf
                     backend evaluates from the children near each point only.

  molecule_1000_deep.json
                     the same 1000 spheres as a left-deep binary tree of two-child smooth
                     unions (999 levels), the form modelling tools export: it must render as
                     the flat molecule_1000.json does (same fold order, same field).
  assembly.json      a branching tree-like assembly: rounded boxes and capsules joined by
                     smooth unions nested per branch (a few hundred primitives, six levels).
  carved.json        a part carved by smooth subtractions (capsule slots, sphere pockets) and
                     rounded by a smooth intersection with a sphere, capped-cone bosses on top.

Usage: scripts/gen_sculpted.py [--seed S]  (default seed 38)
"""
import argparse
import json
import math
import os
import random

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "scenes", "generated", "sculpted")

SIZES = [10, 100, 1000, 10000]
RADIUS = 0.032
BLEND = 0.026
STEP = 0.04
BALL = 0.7
CAMERA_DISTANCE = 2.6
# The direction the camera looks from (normalised below): above, to the side, in front.
CAMERA_DIR = (0.45, 0.4, -1.0)

LIGHTS = [
    {"ambient": {"intensity": 0.2}},
    {"point": {"position": [-4, 8, -6], "intensity": 0.6}},
    {"directional": {"direction": [1, 4, -2], "intensity": 0.2}},
]


def random_walk(n, seed):
    """n centres: a walk of fixed step in random directions, reflected into the ball."""
    rng = random.Random(seed)
    p = (0.0, 0.0, 0.0)
    out = [p]
    while len(out) < n:
        # Uniform direction on the sphere (Marsaglia's method without rejection: z and angle).
        z = rng.uniform(-1.0, 1.0)
        a = rng.uniform(0.0, 2.0 * math.pi)
        s = math.sqrt(1.0 - z * z)
        d = (s * math.cos(a), s * math.sin(a), z)
        q = tuple(p[i] + STEP * d[i] for i in range(3))
        r = math.sqrt(sum(c * c for c in q))
        if r > BALL:
            # Step back towards the centre instead (the walk stays connected).
            q = tuple(p[i] - STEP * d[i] for i in range(3))
        p = q
        out.append(p)
    return out


def molecule(centres, op="smooth_union"):
    n = len(centres)
    centroid = [sum(c[i] for c in centres) / n for i in range(3)]
    norm = math.sqrt(sum(c * c for c in CAMERA_DIR))
    eye = [centroid[i] + CAMERA_DISTANCE * CAMERA_DIR[i] / norm for i in range(3)]
    r5 = lambda v: round(v, 5)
    return {
        "description": f"Sculpted series: a molecule of {n} spheres (radius {RADIUS}) in one "
        + ("smooth union" if op == "smooth_union" else "blend of all children at once")
        + f" (blend radius {BLEND}), a random walk of step {STEP} (scripts/gen_sculpted.py).",
        "camera": camera(eye, centroid),
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [
            {
                "name": "molecule",
                "shape": {
                    op: {
                        "blend_radius": BLEND,
                        "children": [
                            {
                                "shape": {"sphere": {"radius": RADIUS}},
                                "transform": {"translate": [r5(v) for v in c]},
                            }
                            for c in centres
                        ],
                    }
                },
                "material": {"color": [0.85, 0.45, 0.25], "specular_exponent": 40},
            }
        ],
    }


def camera(eye, target, vfov=40):
    r5 = lambda v: round(v, 5)
    return {
        "position": [r5(v) for v in eye],
        "look_at": [r5(v) for v in target],
        "up": [0, 1, 0],
        "vfov_deg": vfov,
        "width": 256,
        "height": 256,
    }


def deep_chain_text(scene):
    """The flat smooth union of `scene` rewritten as a left-deep binary tree, as JSON text
    (built as text: a thousand levels is past the recursion of Python's json module)."""
    union = scene["objects"][0]["shape"]["smooth_union"]
    kids = [json.dumps(c, separators=(",", ":")) for c in union["children"]]
    opener = '{"shape":{"smooth_union":{"blend_radius":%s,"children":[' % json.dumps(union["blend_radius"])
    tree = opener * (len(kids) - 1) + kids[0]
    for k in kids[1:]:
        tree += "," + k + "]}}}"
    scene["description"] = scene["description"].replace(
        "in one smooth union", "in a left-deep binary tree of smooth unions"
    )
    scene["objects"][0]["shape"] = "@TREE@"
    return json.dumps(scene, separators=(",", ":")).replace('"@TREE@"', tree[len('{"shape":') : -1])


def r5v(v):
    return [round(x, 5) for x in v]


def align_y(d, centre):
    """A transform taking the local y axis onto the unit direction `d`, centred at `centre`:
    `rotate_deg` is applied as Rz Ry Rx, and Rz(tz) Rx(tx) y = (-sin tz cos tx, cos tz cos tx,
    sin tx), so tx = asin(d_z) and tz = atan2(-d_x, d_y)."""
    tx = math.degrees(math.asin(max(-1.0, min(1.0, d[2]))))
    tz = math.degrees(math.atan2(-d[0], d[1]))
    return {"translate": r5v(centre), "rotate_deg": [round(tx, 4), 0.0, round(tz, 4)]}


def assembly(rng):
    """A branching assembly: each branch a rounded-box segment with capsule twigs, blended."""

    def branch(base, direction, length, width, depth):
        # Unit direction; the segment's centre half a length along it.
        n = math.sqrt(sum(d * d for d in direction))
        d = [x / n for x in direction]
        centre = [base[i] + 0.5 * length * d[i] for i in range(3)]
        tip = [base[i] + length * d[i] for i in range(3)]
        transform = align_y(d, centre)
        seg = {
            "shape": {"rounded_box": {"half_extents": r5v([width, 0.5 * length, width * 0.8]),
                                      "rounding_radius": round(0.6 * width * 0.8, 5)}},
            "transform": transform,
        }
        kids = [seg]
        if depth > 0:
            for _ in range(3):
                nd = [d[i] + rng.uniform(-0.9, 0.9) for i in range(3)]
                kids.append(branch(tip, nd, length * 0.72, width * 0.7, depth - 1))
        else:
            for _ in range(2):
                nd = [d[i] + rng.uniform(-1.2, 1.2) for i in range(3)]
                nn = math.sqrt(sum(x * x for x in nd))
                nd = [x / nn for x in nd]
                h = length * 0.5
                c = [tip[i] + 0.5 * h * nd[i] for i in range(3)]
                t = align_y(nd, c)
                kids.append({"shape": {"capsule": {"radius": round(width * 0.5, 5), "height": round(h, 5)}},
                             "transform": t})
        return {"shape": {"smooth_union": {"blend_radius": round(0.8 * width, 5), "children": kids}}}

    root = branch([0.0, -0.9, 0.0], [0.0, 1.0, 0.0], 0.7, 0.09, 4)
    root["name"] = "assembly"
    root["material"] = {"color": [0.45, 0.6, 0.35], "specular_exponent": 20}
    return {
        "description": "Sculpted series: a branching assembly of rounded boxes and capsules, smooth "
        "unions nested per branch (scripts/gen_sculpted.py).",
        "camera": camera([1.6, 1.2, -3.6], [0.0, 0.25, 0.0], 45),
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [root],
    }


def carved(rng):
    """A block carved by smooth subtractions, rounded by a smooth intersection."""
    block = {"shape": {"rounded_box": {"half_extents": [0.9, 0.35, 0.6], "rounding_radius": 0.05}}}
    cuts = []
    for i in range(6):
        x = -0.7 + 0.28 * i
        cuts.append({"shape": {"capsule": {"radius": 0.06, "height": 0.7}},
                     "transform": {"translate": [round(x, 5), 0.35, 0.0], "rotate_deg": [90, 0, 0]}})
    for _ in range(24):
        c = [rng.uniform(-0.85, 0.85), rng.choice([-0.35, 0.35]), rng.uniform(-0.55, 0.55)]
        cuts.append({"shape": {"sphere": {"radius": round(rng.uniform(0.04, 0.09), 5)}},
                     "transform": {"translate": r5v(c)}})
    carved_block = {"shape": {"smooth_subtraction": {"blend_radius": 0.03, "children": [block] + cuts}}}
    rounded = {"shape": {"smooth_intersection": {"blend_radius": 0.08, "children": [
        carved_block, {"shape": {"sphere": {"radius": 1.0}}}]}}}
    bosses = [{"shape": {"capped_cone": {"height": 0.2, "bottom_radius": 0.09, "top_radius": 0.05}},
               "transform": {"translate": [round(-0.6 + 0.4 * i, 5), -0.42, 0.3]}} for i in range(4)]
    part = {"name": "part",
            "shape": {"smooth_union": {"blend_radius": 0.04, "children": [rounded] + bosses}},
            "material": {"color": [0.7, 0.72, 0.78], "specular_exponent": 60}}
    return {
        "description": "Sculpted series: a part carved by smooth subtractions, rounded by a smooth "
        "intersection, with capped-cone bosses (scripts/gen_sculpted.py).",
        "camera": camera([1.3, 1.6, -2.4], [0.0, 0.0, 0.0], 45),
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [part],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=38)
    args = ap.parse_args()
    os.makedirs(OUT, exist_ok=True)
    walk = random_walk(max(SIZES), args.seed)
    for n, op in [(n, op) for op in ["smooth_union", "blend"] for n in SIZES]:
        name = f"molecule_{n}.json" if op == "smooth_union" else f"molecule_blend_{n}.json"
        path = os.path.join(OUT, name)
        with open(path, "w") as f:
            # One child a line: readable, and a tenth of the size of an indented dump.
            scene = molecule(walk[:n], op)
            kids = scene["objects"][0]["shape"][op]["children"]
            scene["objects"][0]["shape"][op]["children"] = "@CHILDREN@"
            text = json.dumps(scene, indent=2)
            lines = ",\n".join(" " * 10 + json.dumps(c, separators=(",", ":")) for c in kids)
            f.write(text.replace('"@CHILDREN@"', "[\n" + lines + "\n        ]") + "\n")
        print("wrote", os.path.relpath(path, ROOT))
    path = os.path.join(OUT, "molecule_1000_deep.json")
    with open(path, "w") as f:
        f.write(deep_chain_text(molecule(walk[:1000])) + "\n")
    print("wrote", os.path.relpath(path, ROOT))
    rng = random.Random(args.seed)
    for name, scene in [("assembly", assembly(rng)), ("carved", carved(rng))]:
        path = os.path.join(OUT, f"{name}.json")
        with open(path, "w") as f:
            json.dump(scene, f, separators=(",", ":"))
            f.write("\n")
        print("wrote", os.path.relpath(path, ROOT))


if __name__ == "__main__":
    main()
