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


def molecule(centres):
    n = len(centres)
    centroid = [sum(c[i] for c in centres) / n for i in range(3)]
    norm = math.sqrt(sum(c * c for c in CAMERA_DIR))
    eye = [centroid[i] + CAMERA_DISTANCE * CAMERA_DIR[i] / norm for i in range(3)]
    r5 = lambda v: round(v, 5)
    return {
        "description": f"Sculpted series: a molecule of {n} spheres (radius {RADIUS}) in one smooth "
        f"union (blend radius {BLEND}), a random walk of step {STEP} (scripts/gen_sculpted.py).",
        "camera": {
            "position": [r5(v) for v in eye],
            "look_at": [r5(v) for v in centroid],
            "up": [0, 1, 0],
            "vfov_deg": 40,
            "width": 256,
            "height": 256,
        },
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [
            {
                "name": "molecule",
                "shape": {
                    "smooth_union": {
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


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=38)
    args = ap.parse_args()
    os.makedirs(OUT, exist_ok=True)
    walk = random_walk(max(SIZES), args.seed)
    for n in SIZES:
        path = os.path.join(OUT, f"molecule_{n}.json")
        with open(path, "w") as f:
            # One child a line: readable, and a tenth of the size of an indented dump.
            scene = molecule(walk[:n])
            kids = scene["objects"][0]["shape"]["smooth_union"]["children"]
            scene["objects"][0]["shape"]["smooth_union"]["children"] = "@CHILDREN@"
            text = json.dumps(scene, indent=2)
            lines = ",\n".join(" " * 10 + json.dumps(c, separators=(",", ":")) for c in kids)
            f.write(text.replace('"@CHILDREN@"', "[\n" + lines + "\n        ]") + "\n")
        print("wrote", os.path.relpath(path, ROOT))


if __name__ == "__main__":
    main()
