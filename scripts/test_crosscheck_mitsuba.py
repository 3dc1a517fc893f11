#!/usr/bin/env python3
"""Tests of scripts/crosscheck_mitsuba.py: `python3 -m unittest scripts/test_crosscheck_mitsuba.py`.

The plane geometry (`PlaneSquare`) is pure Python and always runs (`cargo test --test
hostile_scripts` runs this file); the rest is skipped when Mitsuba 3 or numpy is absent
(`pip install mitsuba numpy`). The end-to-end tests also need a built `marchmesh` binary
(`cargo build --release -p marchmesh-cli`, or set MARCHMESH_BIN) and are skipped without one.
"""

import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

try:
    import numpy as np
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    HAVE_MITSUBA = True
except ImportError:
    HAVE_MITSUBA = False

import crosscheck_mitsuba as cm  # noqa: E402  (imports without numpy/mitsuba too)

SCENE = {
    "camera": {"position": [0.7, 1.2, -5], "look_at": [0.2, 0, 0], "vfov_deg": 40, "width": 48, "height": 36},
    "objects": [
        {"shape": {"sphere": {"radius": 0.9}}, "transform": {"translate": [-0.6, 0.1, 0.3]}},
        {"shape": {"plane": {"normal": [0, 3, 0], "offset": -0.8}}},
    ],
    "render": {"max_distance": 100},
}


def render_space(eye, translate=(0, 0, 0)):
    """The 4x4 map from an object's frame (translated by `translate`) to render space."""
    return [[1, 0, 0, translate[0] - eye[0]], [0, 1, 0, translate[1] - eye[1]],
            [0, 0, 1, translate[2] - eye[2]], [0, 0, 0, 1]]


class PlaneSquare(unittest.TestCase):
    """The square standing for a plane, in pure Python (runs without numpy or Mitsuba)."""

    def assert_close(self, a, b, tol=1e-9):
        self.assertEqual(len(a), len(b))
        for x, y in zip(a, b):
            self.assertLess(abs(x - y), tol, f"{a} != {b}")

    def test_the_square_is_centred_below_a_camera_far_from_the_origin(self):
        # A ground plane seen by a camera 3,000 units from the world origin: the square's
        # centre must be the camera's foot point in render space, 1 unit below it, not a point
        # computed from the world-space camera position (3,000 units away, which left most of
        # the visible ground uncovered).
        x, y, z, foot = cm.plane_square(render_space([3000, 1, 0]), [0, 1, 0], 0.0)
        self.assert_close(z, [0, 1, 0])
        self.assert_close(foot, [0, -1, 0])
        for a, b in ((x, y), (y, z), (z, x)):
            self.assertLess(abs(sum(p * q for p, q in zip(a, b))), 1e-12)

    def test_offset_normal_length_scale_and_rotation_follow_the_scene_format(self):
        # offset is along the unit normal whatever the normal's length: y = -0.8.
        _, _, z, foot = cm.plane_square(render_space([0.7, 1.2, -5]), [0, 3, 0], -0.8)
        self.assert_close(z, [0, 1, 0])
        self.assert_close(foot, [0, -2.0, 0])
        # A translated plane, the camera anywhere: the foot is the nearest plane point.
        eye = [1e4, 250.0, -3e3]
        _, _, z, foot = cm.plane_square(render_space(eye, (5, 7, 9)), [0, 0, -2], 1.5)
        self.assert_close(z, [0, 0, -1])
        self.assert_close(foot, [0, 0, 9 - 1.5 - eye[2]], 1e-6)
        # A non-uniform scale maps normals by the inverse transpose: the plane x + y = 0
        # scaled by (2, 1, 1) is x / 2 + y = 0, normal (1, 2, 0) / sqrt(5).
        m = [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
        _, _, z, foot = cm.plane_square(m, [1, 1, 0], 0.0)
        self.assert_close(z, [1 / math.sqrt(5), 2 / math.sqrt(5), 0])
        self.assert_close(foot, [0, 0, 0])
        # A mirroring transform keeps the solid side: the normal flips with the mirror.
        m = [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
        _, _, z, _ = cm.plane_square(m, [1, 0, 0], 0.0)
        self.assert_close(z, [-1, 0, 0])


@unittest.skipUnless(HAVE_MITSUBA, "Mitsuba 3 / numpy not installed: pip install mitsuba numpy")
class Crosscheck(unittest.TestCase):
    def test_mitsuba_depth_matches_an_f64_pinhole_on_sphere_and_plane(self):
        cam = SCENE["camera"]
        w, h = cam["width"], cam["height"]
        depth, _, hit, d = cm.render_mitsuba(mi, SCENE, REPO, w, h)
        eye = np.array(cam["position"], dtype=float)
        oc = eye - np.array([-0.6, 0.1, 0.3])
        b = np.einsum("ijk,k->ij", d, oc)
        disc = b * b - (oc @ oc - 0.81)
        t_sphere = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
        # Plane y = -0.8 (offset along the unit normal, whatever the normal's length).
        t_plane = np.where(d[..., 1] < 0, (-0.8 - eye[1]) / np.where(d[..., 1] < 0, d[..., 1], -1), np.inf)
        t_plane = np.where(t_plane <= 100, t_plane, np.inf)
        truth = np.minimum(t_sphere, t_plane)
        # Pixels whose ray passes within 1e-4 of the sphere's silhouette may go either way.
        clear = np.abs(disc) > 1e-3
        self.assertEqual(int(((np.isfinite(truth) != hit) & clear).sum()), 0)
        both = np.isfinite(truth) & hit & clear
        self.assertGreater(int(both.sum()), w * h // 2)
        rel = np.abs(depth[both] - truth[both]) / truth[both]
        self.assertLess(float(rel.max()), 5e-5)  # Mitsuba is float32

    def test_unsupported_shapes_are_declined_with_their_json_path(self):
        scene = {"objects": [{"shape": {"union": {"children": [{"shape": {"torus": {}}}]}}}]}
        with self.assertRaises(cm.Unsupported) as e:
            cm.Translator(mi, scene, REPO, [0, 0, 0]).build()
        self.assertIn("objects[0].shape.union.children[0].shape.torus", str(e.exception))
        scene = {"objects": [{"shape": {"sphere": {}}, "transform": {"scale": [1, 2, 1]}}]}
        with self.assertRaises(cm.Unsupported):
            cm.Translator(mi, scene, REPO, [0, 0, 0]).build()

    def test_pfm_rows_are_read_bottom_up(self):
        with tempfile.TemporaryDirectory() as tmp:
            p = os.path.join(tmp, "d.pfm")
            rows_bottom_up = np.array([[3, 4], [1, 2]], dtype="<f4")
            with open(p, "wb") as f:
                f.write(b"Pf\n2 2\n-1.0\n" + rows_bottom_up.tobytes())
            np.testing.assert_array_equal(cm.read_pfm(p), [[1, 2], [3, 4]])

    def test_end_to_end_far_from_the_origin_has_no_mismatch(self):
        far = {
            "camera": {"position": [3000, 1, 0], "look_at": [3000, 0.5, 5], "vfov_deg": 50, "width": 64, "height": 64},
            "objects": [{"shape": {"plane": {"normal": [0, 1, 0], "offset": 0}}},
                        {"shape": {"sphere": {"radius": 0.5}}, "transform": {"translate": [3000, 0.5, 4]}}],
        }
        self.end_to_end(far, 64, 64)

    def test_end_to_end_reference_has_no_mismatch(self):
        self.end_to_end(SCENE, 48, 36)

    def end_to_end(self, scene_json, w, h):
        exe = os.environ.get("MARCHMESH_BIN", os.path.join(REPO, "target", "release", "marchmesh"))
        if not os.path.exists(exe):
            self.skipTest(f"no marchmesh binary at {exe}")
        with tempfile.TemporaryDirectory() as tmp:
            scene = os.path.join(tmp, "s.json")
            with open(scene, "w") as f:
                json.dump(scene_json, f)
            aov = os.path.join(tmp, "aov")
            subprocess.run([exe, "render", scene, "--backend", "reference", "--aov", aov,
                            "--out", os.path.join(tmp, "o.png"), "--force"],
                           check=True, capture_output=True)
            res = cm.compare(*cm.render_mitsuba(mi, scene_json, tmp, w, h), aov)
            self.assertLessEqual(res["hit_miss_mismatch"], 1)
            self.assertLess(res["depth_rel_max"], 5e-5)
            self.assertLess(res["normal_deg_max"], 0.05)
            self.assertTrue(math.isfinite(res["depth_rel_mean"]))


if __name__ == "__main__":
    unittest.main()
