#!/usr/bin/env python3
"""Cross-check marchmesh's path tracer against Mitsuba 3's on the same scene.

Translates a marchmesh scene that uses the path tracer into a Mitsuba 3 scene with the same
camera (pixel-centre pinhole, vertical FOV, box pixel filter), renders it with Mitsuba's `path`
integrator and with marchmesh (`marchmesh render --aov`, linear `color.pfm`), each side twice
with independent seeds at half the sample count, and decides by bias against noise:

- **noise**: with `a1, a2` one renderer's two seed images and `b1, b2` the other's, `a` and
  `b` their averages, per pixel (summed over R, G, B) `D = |a - b|^2` and
  `V = (|a1 - a2|^2 + |b1 - b2|^2) / 4`. `V` is an unbiased estimate of the noise part of `D`
  (`E|a1 - a2|^2 / 4` is the variance of `a`), so without bias `E[D - V] = 0` and with a
  per-pixel bias `e`, `E[D - V] = |e|^2`. The check passes when the mean of `D - V` over the
  pixels is at most `Z_MAX` (4) standard errors above 0: the renderers differ by no more
  than the seed-to-seed noise predicts. The standard error is the one the noise alone
  gives, `sqrt(2 mean(V^2) / pixels)` (for Gaussian noise the variance of `D - V` without
  bias lies between 4/3 and 2 times `E[V^2]`, so this errs towards passing), not the spread
  of `D - V` itself, which a bias in a few bright pixels (a mirror showing the light)
  inflates until it hides itself: a mirror rendered as diffuse on one side gave z = 1.5 by
  that spread, 5,228 by this one. `D / V` (1 for pure noise) and the PSNR the noise alone
  predicts are reported.
- **mean**: per channel, the image means agree within `MEAN_REL_TOL` (1%) of Mitsuba's.

So the verdict does not depend on the sample count: a fixed PSNR threshold failed an
unbiased scene at 512 spp that passed at 1024.

Scenes (everything else is declined with its JSON path and exit status 2): the shapes of
`crosscheck_mitsuba.py`'s translation, in render space (sphere, box, cylinder with caps,
plane as a square of side 2 * render.max_distance centred on the camera's foot point,
triangle, OBJ mesh, union, finite repeat, every transform; non-uniformly scaled spheres and
cylinders, other CSG, glTF declined), materials inherited as in marchmesh; each material a
two-sided `blendbsdf` of `diffuse` (albedo `color`) and a perfect mirror (`conductor`,
material `none`) weighted by `reflectivity` (marchmesh's "mirror with probability
reflectivity, else Lambertian"; two-sided because marchmesh turns normals to face the ray);
rectangle, sphere, point and directional lights casting shadows (omitted lights: marchmesh's
default rig); a colour background. A plane's square ends at
max_distance from the camera's foot point, where marchmesh's rays end at max_distance along
themselves: keep max_distance well beyond the lit scene.

Usage (Mitsuba 3 from PyPI, scalar variant, no GPU):

    pip install mitsuba numpy
    cargo build --release -p marchmesh-cli
    python3 scripts/crosscheck_mitsuba_pt.py scenes/lighting/cornell-box.json --size 64 --spp 512

Exit status: 0 when both checks pass, 1 when one fails, 2 on bad input, an inexpressible scene
or a missing tool.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

try:
    import numpy as np
except ImportError:  # the decision rule below is pure Python; main() reports it
    np = None

# Standard errors the renderers' squared difference may exceed the seeds' noise by.
Z_MAX = 4.0
# Relative difference allowed between the renderers' per-channel mean radiance.
MEAN_REL_TOL = 0.01


# --- the decision rule (pure Python: testable without numpy or Mitsuba) -----------------

def verdict(a1, a2, b1, b2, z_max=Z_MAX, mean_rel_tol=MEAN_REL_TOL):
    """Bias against noise for two renderers' images, each rendered with two seeds.

    `a1, a2` (one renderer) and `b1, b2` (the other, the reference for the means) are
    sequences of pixels, each a sequence of channel values (linear radiance). Returns a dict:
    `pixels`, `excess` (mean of D - V, module docs), `excess_se` (its standard error from
    the noise alone), `z`,
    `ratio` (mean D / mean V), `mse` (mean D per channel), `noise_mse` (mean V per channel),
    `means_a`, `means_b`, `mean_rel` (per channel), `noise_ok`, `mean_ok`, `ok`.
    """
    n = len(a1)
    if n < 2 or not (len(a2) == len(b1) == len(b2) == n):
        raise ValueError(f"the four images need the same number of pixels, at least 2 "
                         f"({len(a1)}, {len(a2)}, {len(b1)}, {len(b2)})")
    channels = len(a1[0])
    sums_a = [0.0] * channels
    sums_b = [0.0] * channels
    total_d = total_v = 0.0
    excess = []
    noise = []
    for p in range(n):
        d = v = 0.0
        for c in range(channels):
            x1, x2, y1, y2 = (float(a1[p][c]), float(a2[p][c]), float(b1[p][c]), float(b2[p][c]))
            a, b = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
            sums_a[c] += a
            sums_b[c] += b
            d += (a - b) ** 2
            v += 0.25 * ((x1 - x2) ** 2 + (y1 - y2) ** 2)
        total_d += d
        total_v += v
        excess.append(d - v)
        noise.append(v)
    mean_excess = math.fsum(excess) / n
    se = math.sqrt(2.0 * math.fsum(v * v for v in noise) / n / n)
    if se > 0:
        z = mean_excess / se
    else:
        z = 0.0 if mean_excess <= 0 else math.inf
    means_a = [s / n for s in sums_a]
    means_b = [s / n for s in sums_b]
    mean_rel = [abs(x - y) / max(abs(y), 1e-12) for x, y in zip(means_a, means_b)]
    if not all(math.isfinite(x) for x in means_a + means_b + [total_d, total_v]):
        raise ValueError("non-finite radiance in an image")
    noise_ok = z <= z_max
    mean_ok = all(r <= mean_rel_tol for r in mean_rel)
    return {
        "pixels": n,
        "excess": mean_excess,
        "excess_se": se,
        "z": z,
        "ratio": total_d / total_v if total_v > 0 else (1.0 if total_d == 0 else math.inf),
        "mse": total_d / (n * channels),
        "noise_mse": total_v / (n * channels),
        "means_a": means_a,
        "means_b": means_b,
        "mean_rel": mean_rel,
        "noise_ok": noise_ok,
        "mean_ok": mean_ok,
        "ok": noise_ok and mean_ok,
    }


def psnr_of_mse(mse):
    return math.inf if mse <= 0 else 10 * math.log10(1.0 / mse)


# --- scene translation ---------------------------------------------------------------------

def read_pfm(path):
    """A PFM file as a float64 array (rows from the top, channels last)."""
    with open(path, "rb") as f:
        kind = f.readline().strip()
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        channels = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(height, width, channels)[::-1].astype(np.float64)


def rgb(value):
    return {"type": "rgb", "value": [float(c) for c in value]}


def bsdf(material):
    """marchmesh's path-tracing material as a Mitsuba BSDF (module docs)."""
    diffuse = {"type": "diffuse", "reflectance": rgb(material.get("color", [0.8, 0.8, 0.8]))}
    r = float(material.get("reflectivity", 0.0))
    if r > 0:
        mirror = {"type": "conductor", "material": "none"}
        inner = mirror if r >= 1 else {"type": "blendbsdf", "weight": r,
                                       "bsdf_0": diffuse, "bsdf_1": mirror}
    else:
        inner = diffuse
    return {"type": "twosided", "bsdf": inner}


def mitsuba_scene(mi, scene, scene_dir, size, spp, seed):
    """The Mitsuba scene dictionary equivalent to a marchmesh path-traced scene, in render
    space (the camera at the origin). Raises `crosscheck_mitsuba.Unsupported` or ValueError
    for what cannot be expressed."""
    import crosscheck_mitsuba as cm

    render = scene.get("render", {})
    if render.get("integrator") != "path":
        raise ValueError("render.integrator must be \"path\" (this script checks the path tracer)")
    cam = scene.get("camera", {})
    eye, forward, _, true_up = cm.camera_frame(cam)
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
            "near_clip": cm.NEAR_CLIP,
            "far_clip": float(render.get("max_distance", 1000.0)),
            "to_world": mi.ScalarTransform4f().look_at(
                origin=[0, 0, 0], target=forward.tolist(), up=true_up.tolist()),
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
        raise ValueError("background: only colour backgrounds can be expressed")
    if any(background["color"]):
        out["environment"] = {"type": "constant", "radiance": rgb(background["color"])}
    black = {"type": "diffuse", "reflectance": rgb([0, 0, 0])}
    # Omitted lights are marchmesh's default rig (scenes/README.md); ambient light is ignored.
    lights = scene.get("lights", [{"directional": {"direction": [1, 2, -1], "intensity": 0.8}}])
    for i, light in enumerate(lights):
        (kind, spec), = light.items()
        if not spec.get("casts_shadows", True) and kind != "ambient":
            raise ValueError(f"lights[{i}]: a light that casts no shadows cannot be expressed")
        color = spec.get("color", [1, 1, 1])
        radiance = rgb([spec["intensity"] * c for c in color])
        if kind == "rectangle_light":
            u, v = (np.array(spec[k], dtype=float) for k in ("edge_u", "edge_v"))
            corner = np.array(spec["corner"], dtype=float) - eye
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
                "center": (np.array(spec["position"], dtype=float) - eye).tolist(),
                "radius": spec["radius"],
                "emitter": {"type": "area", "radiance": radiance},
                "bsdf": black,
            }
        elif kind == "point":
            out[f"light{i}"] = {
                "type": "point",
                "position": (np.array(spec["position"], dtype=float) - eye).tolist(),
                "intensity": rgb([spec["intensity"]] * 3),
            }
        elif kind == "directional":
            # marchmesh's direction points towards the light, Mitsuba's along the light.
            to_light = np.array(spec["direction"], dtype=float)
            out[f"light{i}"] = {
                "type": "directional",
                "direction": (-to_light / np.linalg.norm(to_light)).tolist(),
                "irradiance": rgb([spec["intensity"]] * 3),
            }
        elif kind == "ambient":
            pass  # the path tracer ignores ambient light
        else:
            raise ValueError(f"lights[{i}]: {kind} lights cannot be expressed")
    shapes = cm.Translator(mi, scene, scene_dir, eye, bsdf=bsdf).build()
    out.update(shapes)
    return out


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="a marchmesh scene with render.integrator = \"path\"")
    ap.add_argument("--size", type=int, default=64, help="image side in pixels (default 64)")
    ap.add_argument("--spp", type=int, default=1024,
                    help="samples per pixel per renderer, split over two seeds (default 1024)")
    ap.add_argument("--backend", default="reference", help="marchmesh backend (default reference)")
    ap.add_argument("--marchmesh", default=os.path.join("target", "release", "marchmesh"),
                    help="path of the marchmesh binary")
    ap.add_argument("--json", action="store_true", help="print the statistics as JSON")
    args = ap.parse_args(argv)
    if np is None:
        print("error: numpy is missing: pip install mitsuba numpy", file=sys.stderr)
        return 2
    try:
        import mitsuba as mi
    except ImportError:
        print("error: Mitsuba 3 is missing: pip install mitsuba numpy", file=sys.stderr)
        return 2
    mi.set_variant("scalar_rgb")
    import crosscheck_mitsuba as cm

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
                desc = mitsuba_scene(mi, scene, scene_dir, args.size, half, seed)
                images[("mitsuba", seed)] = np.array(mi.render(mi.load_dict(desc)),
                                                     dtype=np.float64)
                images[("marchmesh", seed)] = render_marchmesh(
                    args.marchmesh, scene, scene_dir, args.size, half, seed, args.backend, work,
                    f"seed{seed}")
        except cm.Unsupported as e:
            print(f"error: {args.scene}: cannot be expressed in Mitsuba: {e}", file=sys.stderr)
            return 2
        except (ValueError, KeyError) as e:
            print(f"error: {args.scene}: {e}", file=sys.stderr)
            return 2
    flat = {k: img[..., :3].reshape(-1, 3).tolist() for k, img in images.items()}
    res = verdict(flat[("marchmesh", 1)], flat[("marchmesh", 2)],
                  flat[("mitsuba", 1)], flat[("mitsuba", 2)])
    res.update(scene=args.scene, size=args.size, spp=2 * half, backend=args.backend,
               mitsuba=mi.__version__)
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(f"{args.scene}: {args.size}x{args.size}, {2 * half} spp per renderer "
              f"(2 seeds x {half}), backend {args.backend}, Mitsuba {mi.__version__}")
        for c, name in enumerate("RGB"):
            print(f"  mean {name}: marchmesh {res['means_a'][c]:.5f}  mitsuba "
                  f"{res['means_b'][c]:.5f}  relative difference {res['mean_rel'][c]:.4%}")
        print(f"  squared difference per channel {res['mse']:.4e}, of which noise "
              f"{res['noise_mse']:.4e} (ratio {res['ratio']:.4f})")
        print(f"  excess {res['excess']:.3e} +- {res['excess_se']:.3e} per pixel: "
              f"z = {res['z']:.2f} (pass at <= {Z_MAX})")
        print(f"  PSNR marchmesh vs mitsuba {psnr_of_mse(res['mse']):.2f} dB, "
              f"predicted by the noise alone {psnr_of_mse(res['noise_mse']):.2f} dB")
        if res["ok"]:
            print("PASS")
        else:
            why = []
            if not res["noise_ok"]:
                why.append(f"the difference exceeds the seeds' noise by z = {res['z']:.2f} > {Z_MAX}")
            if not res["mean_ok"]:
                why.append(f"a channel's mean differs by more than {MEAN_REL_TOL:.0%}")
            print("FAIL: " + "; ".join(why))
    return 0 if res["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
