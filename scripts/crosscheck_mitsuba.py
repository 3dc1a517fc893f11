#!/usr/bin/env python3
"""Cross-check a marchmesh render against Mitsuba 3, an independent renderer.

Translates a marchmesh scene (JSON, scenes/README.md) into a Mitsuba 3 scene with the same
pixel-centre camera, renders Mitsuba's depth and normal AOVs, and compares them with the
`--aov` output of any marchmesh backend: hit/miss mismatches, depth errors relative to the
Mitsuba depth, and normal angle errors.

    pip install mitsuba numpy
    marchmesh render scenes/primitives.json --backend reference --aov /tmp/aov --force
    python3 scripts/crosscheck_mitsuba.py scenes/primitives.json /tmp/aov

Mitsuba expresses: sphere (uniform scale), box, cylinder with caps (uniform scale), plane
(a square of side 2 * render.max_distance around the camera's foot point, in render space), triangle, OBJ
mesh, union (its children), repeat with finite counts (the union of whole copies), and
every transform. Anything else (ellipsoid, torus, intersection, subtraction, smooth_union,
infinite repetition, glTF, non-uniformly scaled spheres and cylinders) is declined with
the object's JSON path and exit status 2.

Camera (ANCHORS.md): sensor `perspective`, `fov_axis` y, `near_clip` 1e-6 (Mitsuba's depth
is measured from the near plane: `near_clip / dot(d, forward)` is added back), `hdrfilm`
with a `box` filter, sampler `stratified` with one unjittered sample (the pixel centre),
integrator `aov` with `dd:depth,nn:sh_normal`, variant `scalar_rgb` (no GPU). Mitsuba is
float32: expect depth errors up to ~5e-5 relative on large flat shapes and nothing valid
1e4 units from the origin; the exact reference agrees with it to those bounds.

Exit status: 0 when the comparison ran (and, with --max-mismatch N, at most N hit/miss
mismatches), 1 when more mismatches than allowed, 2 when the scene cannot be expressed or
the inputs are unreadable, 3 when Mitsuba is not installed.
"""

import argparse
import json
import math
import os
import sys

try:
    import numpy as np
except ImportError:  # pragma: no cover - reported below
    np = None

NEAR_CLIP = 1e-6


class Unsupported(Exception):
    """The scene uses something Mitsuba cannot express exactly (message names the path)."""


# --- small affine algebra (4x4 numpy matrices) ------------------------------------------

def translate(t):
    m = np.eye(4)
    m[:3, 3] = t
    return m


def rotate_deg(r):
    """Rz * Ry * Rx, degrees (scenes/README.md)."""
    ax, ay, az = (math.radians(v) for v in r)
    cx, sx, cy, sy, cz, sz = (math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay),
                              math.cos(az), math.sin(az))
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    return m


def scale(s):
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2] = s
    return m


def object_transform(obj):
    t = obj.get("transform", {})
    s = t.get("scale", 1.0)
    if not isinstance(s, list):
        s = [s, s, s]
    return translate(t.get("translate", [0, 0, 0])) @ rotate_deg(t.get("rotate_deg", [0, 0, 0])) @ scale(s)


def uniform_scale(m, path):
    """The scale factor of a similarity transform; Unsupported otherwise."""
    a = m[:3, :3]
    g = a.T @ a
    s2 = g[0, 0]
    if not np.allclose(g, s2 * np.eye(3), rtol=1e-9, atol=1e-12 * max(s2, 1e-300)):
        raise Unsupported(f"{path}: a non-uniform scale here cannot be expressed in Mitsuba")
    return math.sqrt(s2)


# --- planes (pure Python: testable without numpy or Mitsuba) ----------------------------

def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _unit(v):
    n = math.sqrt(_dot(v, v))
    return [x / n for x in v]


def plane_square(m, normal, offset):
    """The frame of the square that stands for a plane: `(x, y, z, foot)`, lists of 3 floats.

    `m` (a 4x4 matrix as nested sequences) maps the plane's frame to render space, where the
    camera is at the origin; the plane is `dot(normal, p) = offset * |normal|` in its frame.
    `z` is the render-space unit normal, `foot` the camera's foot point on the plane (the
    square, of side 2 * max_distance, is centred there, so it covers every point of the plane
    within max_distance of the camera), `x` and `y` complete a right-handed frame.
    """
    nl = _unit([float(v) for v in normal])
    a = [[float(m[i][j]) for j in range(3)] for i in range(3)]
    # Normals map by the inverse transpose of the linear part: its cofactor matrix (the
    # determinant only scales, and the result is normalised).
    cof = [[a[(i + 1) % 3][(j + 1) % 3] * a[(i + 2) % 3][(j + 2) % 3]
            - a[(i + 1) % 3][(j + 2) % 3] * a[(i + 2) % 3][(j + 1) % 3] for j in range(3)]
           for i in range(3)]
    det = _dot(a[0], cof[0])
    z = _unit([_dot(cof[i], nl) * (1.0 if det > 0 else -1.0) for i in range(3)])
    local = [offset * v for v in nl]
    point = [_dot(a[i], local) + float(m[i][3]) for i in range(3)]
    # The camera is the render-space origin: its foot point is the plane point nearest to it.
    along = _dot(point, z)
    foot = [along * v for v in z]
    helper = [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0]
    x = _unit(_cross(helper, z))
    y = _cross(z, x)
    return x, y, z, foot


# --- scene translation -------------------------------------------------------------------

class Translator:
    """The scene's objects as Mitsuba shapes in render space.

    `bsdf` (optional) maps an object's effective material (its own, else the one it inherits
    from its CSG or repeat parent, else `{}`) to a Mitsuba BSDF dictionary given to each of its
    shapes; without it shapes get none (Mitsuba's default), which the depth AOVs ignore.
    """

    def __init__(self, mi, scene, scene_dir, camera_position, bsdf=None):
        self.mi = mi
        self.scene = scene
        self.scene_dir = scene_dir
        self.bsdf = bsdf
        self.eye = np.array(camera_position, dtype=float)
        self.max_distance = scene.get("render", {}).get("max_distance", 1000.0)
        self.shapes = {}
        # Render space (camera at the origin), as marchmesh itself renders: keeps float32
        # precise near the camera.
        self.to_render = translate(-self.eye)

    def add(self, shape, material=None):
        if self.bsdf is not None and isinstance(shape, dict):
            shape["bsdf"] = self.bsdf(material or {})
        self.shapes[f"shape_{len(self.shapes)}"] = shape

    def xf(self, m):
        return self.mi.ScalarTransform4f(m.tolist())

    def node(self, obj, parent, path, material=None):
        m = parent @ object_transform(obj)
        material = obj.get("material", material)
        shape = obj.get("shape")
        if not isinstance(shape, dict) or len(shape) != 1:
            raise Unsupported(f"{path}.shape: expected one shape")
        kind, p = next(iter(shape.items()))
        p = p or {}
        spath = f"{path}.shape.{kind}"
        if kind == "sphere":
            s = uniform_scale(m, spath)
            self.add({"type": "sphere", "center": m[:3, 3].tolist(), "radius": s * p.get("radius", 1.0)},
                     material)
        elif kind == "box":
            h = p.get("half_extents", [0.5, 0.5, 0.5])
            self.add({"type": "cube", "to_world": self.xf(m @ scale(h))}, material)
        elif kind == "cylinder":
            s = uniform_scale(m, spath)
            r, hh = p.get("radius", 0.5), 0.5 * p.get("height", 1.0)
            p0 = (m @ np.array([0, -hh, 0, 1]))[:3]
            p1 = (m @ np.array([0, hh, 0, 1]))[:3]
            self.add({"type": "cylinder", "p0": p0.tolist(), "p1": p1.tolist(), "radius": s * r},
                     material)
            # Caps: Mitsuba's disk is the unit disk in z = 0 with normal +z; rotate it onto y.
            onto_y = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)
            for y in (-hh, hh):
                self.add({"type": "disk", "to_world": self.xf(m @ translate([0, y, 0]) @ onto_y @ scale([r, r, 1]))},
                         material)
        elif kind == "triangle":
            v = np.array(p["vertices"], dtype=float)
            w = [(m @ np.append(x, 1.0))[:3] for x in v]
            props = self.mi.Properties()
            if self.bsdf is not None:
                props["bsdf"] = self.mi.load_dict(self.bsdf(material or {}))
            mesh = self.mi.Mesh(f"triangle_{len(self.shapes)}", 3, 1, props)
            params = self.mi.traverse(mesh)
            params["vertex_positions"] = np.array(w, dtype=np.float32).ravel()
            params["faces"] = np.array([0, 1, 2], dtype=np.uint32)
            params.update()
            self.add(mesh)
        elif kind == "mesh":
            f = p["path"]
            if not f.lower().endswith(".obj"):
                raise Unsupported(f"{spath}.path: only OBJ meshes are translated ({f})")
            full = f if os.path.isabs(f) else os.path.join(self.scene_dir, f)
            # marchmesh interpolates the file's vertex normals and uses face normals when the
            # file has none; Mitsuba would compute smooth normals then: ask for face normals.
            with open(full, "rb") as fh:
                has_normals = any(line.startswith(b"vn ") for line in fh)
            self.add({"type": "obj", "filename": full, "to_world": self.xf(m),
                      "face_normals": not has_normals}, material)
        elif kind == "plane":
            x, y, z, foot = plane_square(m.tolist(), p.get("normal", [0, 1, 0]), p.get("offset", 0.0))
            frame = np.eye(4)
            frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = x, y, z, foot
            self.add({"type": "rectangle",
                      "to_world": self.xf(frame @ scale([self.max_distance] * 2 + [1]))}, material)
        elif kind == "union":
            for i, c in enumerate(p.get("children", [])):
                self.node(c, m, f"{spath}.children[{i}]", material)
        elif kind == "repeat":
            period = p.get("period", [0, 0, 0])
            count = p.get("count", [None, None, None])
            ranges = []
            for a in range(3):
                if period[a] > 0:
                    if count[a] is None:
                        raise Unsupported(f"{spath}.count[{a}]: infinite repetition cannot be expressed")
                    n = count[a]
                    ranges.append([(k - (n - 1) / 2) * period[a] for k in range(n)])
                else:
                    ranges.append([0.0])
            for ox in ranges[0]:
                for oy in ranges[1]:
                    for oz in ranges[2]:
                        self.node(p["child"], m @ translate([ox, oy, oz]), f"{spath}.child", material)
        else:
            raise Unsupported(f"{spath}: {kind} has no exact Mitsuba counterpart")

    def build(self):
        for i, obj in enumerate(self.scene.get("objects", [])):
            self.node(obj, self.to_render, f"objects[{i}]")
        return self.shapes


def camera_frame(cam):
    pos = np.array(cam.get("position", [0, 0, 0]), dtype=float)
    look = np.array(cam.get("look_at", [0, 0, 1]), dtype=float)
    up = np.array(cam.get("up", [0, 1, 0]), dtype=float)
    forward = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    return pos, forward, right, true_up


def pixel_directions(cam, w, h):
    """Unit directions of the pixel-centre rays (README camera model), shape (h, w, 3)."""
    _, forward, right, true_up = camera_frame(cam)
    half_h = math.tan(math.radians(cam.get("vfov_deg", 60.0)) / 2)
    i = np.arange(w) + 0.5
    j = np.arange(h) + 0.5
    x = (2 * i / w - 1) * half_h * w / h
    y = (1 - 2 * j / h) * half_h
    d = forward[None, None, :] + x[None, :, None] * right[None, None, :] + y[:, None, None] * true_up[None, None, :]
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def render_mitsuba(mi, scene, scene_dir, w, h):
    cam = scene.get("camera", {})
    pos, forward, right, true_up = camera_frame(cam)
    max_distance = float(scene.get("render", {}).get("max_distance", 1000.0))
    shapes = Translator(mi, scene, scene_dir, pos).build()
    # Mitsuba's camera looks along +z of its frame with +x to the image's left, as marchmesh's
    # right = cross(forward, up) is: look_at from the render-space origin.
    to_world = mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=forward.tolist(), up=true_up.tolist())
    desc = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": "dd:depth,nn:sh_normal"},
        "sensor": {
            "type": "perspective",
            "fov_axis": "y",
            "fov": cam.get("vfov_deg", 60.0),
            "near_clip": NEAR_CLIP,
            # Along the view axis: covers every point within max_distance along a ray.
            "far_clip": max_distance * 1.01,
            "to_world": to_world,
            "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}},
            "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
        },
        **shapes,
    }
    msc = mi.load_dict(desc)
    img = np.array(mi.render(msc, spp=1), dtype=np.float64)
    names = list(msc.integrator().aov_names())
    if names != ["dd.T", "nn.X", "nn.Y", "nn.Z"] or img.shape != (h, w, 4):
        raise ValueError(f"unexpected Mitsuba AOV layout {names}, image {img.shape}")
    depth, normal = img[..., 0], img[..., 1:4]
    d = pixel_directions(cam, w, h)
    # Mitsuba measures depth from the near plane: add the near-clip distance along the ray.
    depth = np.where(depth > 0, depth + NEAR_CLIP / np.einsum("ijk,k->ij", d, forward), np.inf)
    # The far clip plane cuts by distance along the view axis; marchmesh stops rays at
    # max_distance along the ray, so off-axis hits between the two are misses.
    hit = depth <= max_distance
    depth = np.where(hit, depth, np.inf)
    return depth, normal, hit, d


def read_pfm(path):
    with open(path, "rb") as f:
        tag = f.readline().strip()
        if tag not in (b"PF", b"Pf"):
            raise ValueError(f"{path}: not a PFM file")
        w, h = (int(v) for v in f.readline().split())
        sc = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if sc < 0 else ">f4")
    c = 3 if tag == b"PF" else 1
    if data.size != w * h * c:
        raise ValueError(f"{path}: {data.size} floats for a {w}x{h}x{c} image")
    img = data.reshape(h, w, c)[::-1].astype(np.float64)  # rows stored bottom-up
    return img[..., 0] if c == 1 else img


def compare(depth_m, normal_m, hit_m, d, aov_dir):
    depth_b = read_pfm(os.path.join(aov_dir, "depth.pfm"))
    normal_b = read_pfm(os.path.join(aov_dir, "normal.pfm"))
    if depth_b.shape != depth_m.shape:
        raise ValueError(f"{aov_dir}: AOVs are {depth_b.shape[1]}x{depth_b.shape[0]}, the scene {depth_m.shape[1]}x{depth_m.shape[0]}")
    hit_b = np.isfinite(depth_b)
    both = hit_b & hit_m
    rel = np.abs(depth_b[both] - depth_m[both]) / depth_m[both]
    # Mitsuba's shading normals are not flipped toward the viewer; marchmesh's face the ray.
    nm = normal_m / np.maximum(np.linalg.norm(normal_m, axis=2, keepdims=True), 1e-30)
    nm = np.where((np.einsum("ijk,ijk->ij", nm, d) > 0)[..., None], -nm, nm)
    nb = normal_b / np.maximum(np.linalg.norm(normal_b, axis=2, keepdims=True), 1e-30)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ijk,ijk->ij", nm, nb), -1, 1)))[both]
    out = {
        "pixels": int(depth_m.size),
        "hit_mitsuba": int(hit_m.sum()),
        "hit_marchmesh": int(hit_b.sum()),
        "hit_miss_mismatch": int((hit_b != hit_m).sum()),
        "both_hit": int(both.sum()),
    }
    if both.any():
        out.update({
            "depth_rel_mean": float(rel.mean()),
            "depth_rel_p95": float(np.quantile(rel, 0.95)),
            "depth_rel_max": float(rel.max()),
            "depth_rel_over_1e-3_px": int((rel > 1e-3).sum()),
            "normal_deg_mean": float(ang.mean()),
            "normal_deg_p95": float(np.quantile(ang, 0.95)),
            "normal_deg_max": float(ang.max()),
            "normal_over_5deg_px": int((ang > 5).sum()),
        })
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="marchmesh scene JSON")
    ap.add_argument("aov_dir", help="folder of a marchmesh render's --aov output (depth.pfm, normal.pfm)")
    ap.add_argument("--max-mismatch", type=int, default=None,
                    help="exit 1 when more pixels than this are hit by only one renderer")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    if np is None:
        print("numpy is not installed: pip install mitsuba numpy", file=sys.stderr)
        return 3
    try:
        import mitsuba as mi
    except ImportError:
        print("Mitsuba 3 is not installed: pip install mitsuba numpy", file=sys.stderr)
        return 3
    mi.set_variant("scalar_rgb")
    try:
        with open(args.scene) as f:
            scene = json.load(f)
        cam = scene.get("camera", {})
        w, h = cam.get("width", 500), cam.get("height", 500)
        depth, normal, hit, d = render_mitsuba(mi, scene, os.path.dirname(os.path.abspath(args.scene)), w, h)
        res = compare(depth, normal, hit, d, args.aov_dir)
    except Unsupported as e:
        print(f"{args.scene}: cannot be expressed in Mitsuba: {e}", file=sys.stderr)
        return 2
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as e:
        print(f"{args.scene}: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(res, indent=2))
    else:
        print(f"{args.scene}: {w}x{h}, Mitsuba {mi.__version__} vs {args.aov_dir}")
        for k, v in res.items():
            print(f"  {k:24} {v:.3e}" if isinstance(v, float) else f"  {k:24} {v}")
    if args.max_mismatch is not None and res["hit_miss_mismatch"] > args.max_mismatch:
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
