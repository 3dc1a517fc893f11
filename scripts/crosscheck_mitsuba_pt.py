#!/usr/bin/env python3
"""Cross-check marchmesh's path tracer against Mitsuba 3's on the same scene.

Translates a marchmesh scene that uses the path tracer (boxes, spheres, rectangle and sphere
lights, Lambertian materials, a colour background) into a Mitsuba 3 scene with the same camera
(pixel-centre pinhole, vertical FOV), renders it with Mitsuba's `path` integrator, renders it
with marchmesh (`marchmesh render --aov`, linear `color.pfm`) and compares:

- per-channel mean radiance (relative difference; the check passes below 1%),
- PSNR of the two images clamped to [0, 1] (passes at >= 35 dB),
- each image's own noise, estimated from two independent half-sample renders, so a failed
  check can be told apart from too few samples.

Usage (Mitsuba 3 from PyPI, scalar variant, no GPU):

    pip install mitsuba numpy
    cargo build --release -p marchmesh-cli
    python3 scripts/crosscheck_mitsuba_pt.py scenes/lighting/cornell-box.json --size 64 --spp 1024

Exit status: 0 when both checks pass, 1 when one fails, 2 on bad input or a missing tool.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

try:
    import numpy as np
except ImportError:  # pragma: no cover
    sys.exit("error: numpy is missing: pip install mitsuba numpy")


def read_pfm(path):
    """A PFM file as a float32 array (rows from the top, channels last)."""
    with open(path, "rb") as f:
        kind = f.readline().strip()
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        channels = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(height, width, channels)[::-1].astype(np.float64)


def transform(mi, obj):
    """The object-to-world transform `translate * Rz Ry Rx * (scale)` of a marchmesh object."""
    t = obj.get("transform", {})
    translate = t.get("translate", [0, 0, 0])
    rx, ry, rz = t.get("rotate_deg", [0, 0, 0])
    scale = t.get("scale", [1, 1, 1])
    if isinstance(scale, (int, float)):
        scale = [scale] * 3
    m = mi.ScalarTransform4f().translate(translate)
    m = m.rotate([0, 0, 1], rz).rotate([0, 1, 0], ry).rotate([1, 0, 0], rx)
    return m.scale(scale)


def rgb(value):
    return {"type": "rgb", "value": [float(c) for c in value]}


def mitsuba_scene(mi, scene, size, spp, seed):
    """The Mitsuba scene dictionary equivalent to a marchmesh path-traced scene."""
    render = scene.get("render", {})
    if render.get("integrator") != "path":
        raise ValueError("render.integrator must be \"path\" (this script checks the path tracer)")
    cam = scene["camera"]
    out = {
        "type": "scene",
        "integrator": {
            "type": "path",
            # Mitsuba counts the camera segment and the light segment: depth 2 is direct light,
            # marchmesh's max_bounces 0.
            "max_depth": int(render.get("max_bounces", 8)) + 2,
        },
        "sensor": {
            "type": "perspective",
            "fov_axis": "y",
            "fov": float(cam.get("vfov_deg", 60)),
            "near_clip": 1e-4,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=cam.get("position", [0, 0, -5]),
                target=cam.get("look_at", [0, 0, 0]),
                up=cam.get("up", [0, 1, 0]),
            ),
            "film": {
                "type": "hdrfilm",
                "width": size,
                "height": size,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
    }
    background = scene.get("background", {"color": [0, 0, 0]})
    if "color" not in background:
        raise ValueError("only colour backgrounds can be expressed")
    if any(background["color"]):
        out["environment"] = {"type": "constant", "radiance": rgb(background["color"])}
    for i, light in enumerate(scene.get("lights", [])):
        (kind, spec), = light.items()
        color = spec.get("color", [1, 1, 1])
        radiance = rgb([spec["intensity"] * c for c in color])
        black = {"type": "diffuse", "reflectance": rgb([0, 0, 0])}
        if kind == "rectangle_light":
            u, v, corner = (np.array(spec[k], dtype=float) for k in ("edge_u", "edge_v", "corner"))
            n = np.cross(u, v)
            n /= np.linalg.norm(n)
            centre = corner + 0.5 * (u + v)
            # Mitsuba's rectangle spans [-1, 1]^2 in z = 0 and emits towards +z.
            matrix = np.identity(4)
            matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = 0.5 * u, 0.5 * v, n, centre
            out[f"light{i}"] = {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f(matrix.tolist()),
                "emitter": {"type": "area", "radiance": radiance},
                "bsdf": black,
            }
        elif kind == "sphere_light":
            out[f"light{i}"] = {
                "type": "sphere",
                "center": spec["position"],
                "radius": spec["radius"],
                "emitter": {"type": "area", "radiance": radiance},
                "bsdf": black,
            }
        elif kind == "point":
            out[f"light{i}"] = {
                "type": "point",
                "position": spec["position"],
                "intensity": rgb([spec["intensity"]] * 3),
            }
        elif kind == "ambient":
            pass  # the path tracer ignores ambient light
        else:
            raise ValueError(f"lights[{i}]: {kind} lights cannot be expressed")
    for i, obj in enumerate(scene.get("objects", [])):
        material = obj.get("material", {})
        if material.get("reflectivity", 0):
            raise ValueError(f"objects[{i}]: mirrors are not translated by this script")
        bsdf = {"type": "diffuse", "reflectance": rgb(material.get("color", [0.8, 0.8, 0.8]))}
        (kind, spec), = obj["shape"].items()
        if kind == "box":
            half = spec.get("half_extents", [0.5, 0.5, 0.5])
            shape = {"type": "cube", "to_world": transform(mi, obj).scale(half)}
        elif kind == "sphere":
            shape = {"type": "sphere", "radius": spec.get("radius", 1.0),
                     "to_world": transform(mi, obj)}
        else:
            raise ValueError(f"objects[{i}]: {kind} is not translated by this script")
        shape["bsdf"] = bsdf
        out[f"object{i}"] = shape
    return out


def psnr(a, b):
    mse = float(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(1.0 / mse)


def render_marchmesh(binary, scene, scene_dir, size, spp, seed, backend, workdir, tag):
    scene = json.loads(json.dumps(scene))
    scene["camera"]["width"] = scene["camera"]["height"] = size
    scene["render"]["samples_per_pixel"] = spp
    scene["render"]["seed"] = seed
    path = os.path.join(scene_dir, f".crosscheck-{os.getpid()}-{tag}.json")
    with open(path, "w") as f:
        json.dump(scene, f)
    try:
        aov = os.path.join(workdir, f"aov-{tag}")
        cmd = [binary, "render", path, "--backend", backend, "--out",
               os.path.join(workdir, f"{tag}.png"), "--aov", aov]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        return read_pfm(os.path.join(aov, "color.pfm"))
    finally:
        os.remove(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="a marchmesh scene with render.integrator = \"path\"")
    ap.add_argument("--size", type=int, default=64, help="image side in pixels (default 64)")
    ap.add_argument("--spp", type=int, default=1024, help="samples per pixel (default 1024)")
    ap.add_argument("--backend", default="reference", help="marchmesh backend (default reference)")
    ap.add_argument("--marchmesh", default=os.path.join("target", "release", "marchmesh"),
                    help="path of the marchmesh binary")
    args = ap.parse_args()
    try:
        import mitsuba as mi
    except ImportError:
        print("error: Mitsuba 3 is missing: pip install mitsuba numpy", file=sys.stderr)
        return 2
    mi.set_variant("scalar_rgb")
    if not os.path.exists(args.marchmesh):
        print(f"error: {args.marchmesh} not found: cargo build --release -p marchmesh-cli",
              file=sys.stderr)
        return 2
    with open(args.scene) as f:
        scene = json.load(f)
    scene_dir = os.path.dirname(os.path.abspath(args.scene))
    half = max(1, args.spp // 2)
    images = {}
    with tempfile.TemporaryDirectory() as work:
        try:
            for seed in (1, 2):
                images[("mitsuba", seed)] = np.array(
                    mi.render(mi.load_dict(mitsuba_scene(mi, scene, args.size, half, seed))),
                    dtype=np.float64)
                images[("marchmesh", seed)] = render_marchmesh(
                    args.marchmesh, scene, scene_dir, args.size, half, seed, args.backend, work,
                    f"seed{seed}")
        except (ValueError, KeyError) as e:
            print(f"error: {args.scene}: {e}", file=sys.stderr)
            return 2
    mits = (images[("mitsuba", 1)] + images[("mitsuba", 2)]) / 2
    ours = (images[("marchmesh", 1)] + images[("marchmesh", 2)]) / 2
    print(f"{args.scene}: {args.size}x{args.size}, {2 * half} spp, backend {args.backend}")
    ok = True
    for c, name in enumerate("RGB"):
        a, b = float(ours[..., c].mean()), float(mits[..., c].mean())
        rel = abs(a - b) / max(abs(b), 1e-12)
        ok &= rel < 0.01
        print(f"  mean {name}: marchmesh {a:.5f}  mitsuba {b:.5f}  relative difference {rel:.4%}")
    p = psnr(ours, mits)
    ok &= p >= 35.0
    print(f"  PSNR marchmesh vs mitsuba: {p:.2f} dB")
    # Each renderer's own noise: its two half-sample images against each other. The PSNR of
    # the averaged image against the truth is about this plus 6 dB (half the variance).
    for who in ("marchmesh", "mitsuba"):
        print(f"  {who} half vs half: {psnr(images[(who, 1)], images[(who, 2)]):.2f} dB")
    print("PASS" if ok else "FAIL (means within 1% and PSNR >= 35 dB required)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
