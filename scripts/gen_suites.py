#!/usr/bin/env python3
"""Writes the generated scenes of the `scaling` (and `default`) benchmark suites into
scenes/generated/. Deterministic; rerun after changing it and commit the output.

Series (the source study's question: when is ray marching more efficient than polygons?):
  repeat_<n>.json   n = 1, 9, 100, 1024, 10000 spheres in a square grid, and repeat_inf.json
                    (infinite grid); same camera, so the visible work grows with n.
  sphere.json       one sphere, tessellated by the suite at fixed levels up to ~1M triangles.
  mesh_<name>.json  teapot, bunny, dragon_res3 and dragon_full (the last fetched by
                    scripts/fetch_dragon.sh; the suite marks it optional).
"""
import json
import math
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "scenes", "generated")

LIGHTS = [
    {"ambient": {"intensity": 0.2}},
    {"point": {"position": [-4, 8, -6], "intensity": 0.6}},
    {"directional": {"direction": [1, 4, -2], "intensity": 0.2}},
]
FLOOR = {
    "name": "floor",
    "shape": {"plane": {"normal": [0, 1, 0], "offset": 0}},
    "material": {"color": [0.7, 0.7, 0.7]},
}


def write(name, scene):
    path = os.path.join(OUT, name)
    with open(path, "w") as f:
        json.dump(scene, f, indent=2)
        f.write("\n")
    print("wrote", os.path.relpath(path, ROOT))


def repeat_scene(n):
    """n spheres (radius 0.4, period 1) in a k x k grid (k = sqrt n), or infinite."""
    if n is None:
        count, k = [None, 1, None], 100
    else:
        k = int(round(math.sqrt(n)))
        assert k * k == n, n
        count = [k, 1, k]
    # Camera framing the whole grid from above at 45 degrees.
    d = max(3.0, 0.9 * k)
    return {
        "description": f"Repetition series: {'infinitely many' if n is None else n} spheres in a grid "
        "(one repeat node; the mesh backend instances one sphere BLAS, the sdf backend folds space).",
        "camera": {
            "position": [0, d, -d],
            "look_at": [0, 0, 0],
            "up": [0, 1, 0],
            "vfov_deg": 50,
            "width": 320,
            "height": 240,
        },
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [
            FLOOR,
            {
                "name": "grid",
                "shape": {
                    "repeat": {
                        "period": [1, 0, 1],
                        "count": count,
                        "child": {"shape": {"sphere": {"radius": 0.4}}},
                    }
                },
                "transform": {"translate": [0, 0.4, 0]},
                "material": {"color": [0.8, 0.3, 0.2], "specular_exponent": 50},
            },
        ],
        "render": {"max_distance": 200},
    }


def sphere_scene():
    return {
        "description": "Tessellation series: one unit sphere filling the view.",
        "camera": {"position": [0, 0, -3], "look_at": [0, 0, 0], "up": [0, 1, 0],
                   "vfov_deg": 45, "width": 320, "height": 320},
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [{"name": "sphere", "shape": {"sphere": {"radius": 1}},
                     "material": {"color": [0.8, 0.3, 0.2], "specular_exponent": 50}}],
    }


# name -> (scale, translate) putting the mesh about 2 units tall on the floor at the origin.
MESHES = {
    "teapot": (0.07, [0.0, 0.55, 0.0]),
    "bunny": (0.2, [0.0, 0.0, 0.0]),
    "dragon_res3": (10.0, [0.06, -0.53, 0.05]),
    "dragon_full": (10.0, [0.06, -0.53, 0.05]),
}


def mesh_scene(name, scale, translate):
    return {
        "description": f"Mesh-size series: {name} (scenes/meshes/{name}.obj) on a floor.",
        "camera": {"position": [0, 1.5, -4], "look_at": [0, 0.8, 0], "up": [0, 1, 0],
                   "vfov_deg": 45, "width": 320, "height": 240},
        "background": {"color": [0.6, 0.75, 0.9]},
        "lights": LIGHTS,
        "objects": [
            FLOOR,
            {"name": name, "shape": {"mesh": {"path": f"../meshes/{name}.obj"}},
             "transform": {"translate": translate, "scale": scale},
             "material": {"color": [0.8, 0.8, 0.75], "specular_exponent": 20}},
        ],
    }


def main():
    os.makedirs(OUT, exist_ok=True)
    # Square grids: 1, 9 (~10), 100, 1024 (~10^3), 10000, and infinite.
    for n in [1, 9, 100, 1024, 10000, None]:
        write(f"repeat_{'inf' if n is None else n}.json", repeat_scene(n))
    write("sphere.json", sphere_scene())
    for name, (scale, translate) in MESHES.items():
        write(f"mesh_{name}.json", mesh_scene(name, scale, translate))


if __name__ == "__main__":
    main()
