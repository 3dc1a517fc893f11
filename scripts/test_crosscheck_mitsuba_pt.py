#!/usr/bin/env python3
"""Tests of scripts/crosscheck_mitsuba_pt.py: `python3 -m unittest scripts/test_crosscheck_mitsuba_pt.py`.

The decision rule (`Verdict`) is pure Python on synthetic images and always runs (`cargo test
--test hostile_scripts` runs it); the scene translation is skipped when Mitsuba 3 or numpy is
absent (`pip install mitsuba numpy`).
"""

import math
import os
import random
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)

try:
    import numpy as np  # noqa: F401
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    HAVE_MITSUBA = True
except ImportError:
    HAVE_MITSUBA = False

import crosscheck_mitsuba_pt as pt  # noqa: E402  (imports without numpy/mitsuba too)


def noisy(truth, sigma, rng):
    """One seed's render: `truth` (pixels of RGB) plus independent Gaussian noise `sigma`."""
    return [[c + rng.gauss(0.0, sigma) for c in px] for px in truth]


def image(n, rng):
    """A smooth synthetic radiance image of `n` pixels, values around 0.2-0.8."""
    return [[0.5 + 0.3 * math.sin(0.01 * p + c), 0.4, 0.2 + 0.1 * math.cos(0.03 * p)] for p, c in
            zip(range(n), [rng.random() for _ in range(n)])]


class Verdict(unittest.TestCase):
    """The bias-against-noise rule on synthetic images (runs without numpy or Mitsuba)."""

    N = 4096  # a 64x64 image

    def test_unbiased_renders_pass_whatever_their_noise(self):
        # Each side its own noise level, as two renderers at one sample count have. The
        # noisier case is what a fixed PSNR threshold failed: about 30 dB.
        for seed in range(8):
            rng = random.Random(seed)
            truth = image(self.N, rng)
            for sa, sb in ((0.004, 0.006), (0.02, 0.03)):
                r = pt.verdict(noisy(truth, sa, rng), noisy(truth, sa, rng),
                               noisy(truth, sb, rng), noisy(truth, sb, rng))
                self.assertTrue(r["ok"], (seed, sa, sb, r["z"], r["mean_rel"]))
                self.assertLess(abs(r["ratio"] - 1.0), 0.1, r["ratio"])
        self.assertLess(pt.psnr_of_mse(r["mse"]), 35.0)

    def test_a_bias_hidden_in_the_mean_fails_the_noise_check(self):
        # Half the pixels brighter, half darker by half the per-side noise: the means agree
        # exactly, the per-pixel difference does not.
        rng = random.Random(1)
        truth = image(self.N, rng)
        shifted = [[c + (0.01 if p % 2 else -0.01) for c in px] for p, px in enumerate(truth)]
        r = pt.verdict(noisy(shifted, 0.02, rng), noisy(shifted, 0.02, rng),
                       noisy(truth, 0.02, rng), noisy(truth, 0.02, rng))
        self.assertTrue(r["mean_ok"], r["mean_rel"])
        self.assertFalse(r["noise_ok"])
        self.assertFalse(r["ok"])
        self.assertGreater(r["z"], pt.Z_MAX)

    def test_a_large_bias_in_a_few_pixels_fails_the_noise_check(self):
        # A mirror shown as diffuse: 12 of 4096 pixels off by 20 noise deviations, the rest
        # unbiased. The spread of D - V is dominated by those pixels, so it cannot be the
        # standard error; the noise's is.
        rng = random.Random(4)
        truth = image(self.N, rng)
        hot = [[c + (0.4 if p % 341 == 0 else 0.0) for c in px] for p, px in enumerate(truth)]
        r = pt.verdict(noisy(hot, 0.02, rng), noisy(hot, 0.02, rng),
                       noisy(truth, 0.02, rng), noisy(truth, 0.02, rng))
        self.assertTrue(r["mean_ok"], r["mean_rel"])
        self.assertFalse(r["noise_ok"])
        self.assertGreater(r["z"], 20)

    def test_a_uniform_bias_beyond_the_mean_tolerance_fails(self):
        rng = random.Random(2)
        truth = image(self.N, rng)
        brighter = [[1.02 * c for c in px] for px in truth]
        r = pt.verdict(noisy(brighter, 0.05, rng), noisy(brighter, 0.05, rng),
                       noisy(truth, 0.05, rng), noisy(truth, 0.05, rng))
        self.assertFalse(r["mean_ok"])
        self.assertFalse(r["ok"])
        self.assertGreater(min(r["mean_rel"]), pt.MEAN_REL_TOL)
        # Within the tolerance, the same noise passes.
        slightly = [[1.002 * c for c in px] for px in truth]
        r = pt.verdict(noisy(slightly, 0.05, rng), noisy(slightly, 0.05, rng),
                       noisy(truth, 0.05, rng), noisy(truth, 0.05, rng))
        self.assertTrue(r["ok"], (r["z"], r["mean_rel"]))

    def test_noiseless_images_pass_only_when_equal(self):
        truth = image(64, random.Random(3))
        r = pt.verdict(truth, truth, truth, truth)
        self.assertTrue(r["ok"])
        self.assertEqual((r["z"], r["ratio"]), (0.0, 1.0))
        other = [[c + 1e-3 for c in px] for px in truth]
        r = pt.verdict(other, other, truth, truth)
        self.assertFalse(r["noise_ok"])
        self.assertGreater(r["z"], 1e6)

    def test_the_statistic_is_the_excess_of_the_squared_difference_over_the_noise(self):
        # Two pixels, one channel: a = (1 + 3) / 2 = 2, b = (0 + 2) / 2 = 1, D = 1,
        # V = ((1 - 3)^2 + (0 - 2)^2) / 4 = 2, so D - V = -1; second pixel all zero. The
        # standard error is sqrt(2 mean(V^2) / n) = sqrt(2 * 2 / 2) = sqrt(2).
        r = pt.verdict([[1.0], [0.0]], [[3.0], [0.0]], [[0.0], [0.0]], [[2.0], [0.0]])
        self.assertAlmostEqual(r["excess"], -0.5)
        self.assertAlmostEqual(r["excess_se"], math.sqrt(2.0))
        self.assertAlmostEqual(r["z"], -0.5 / math.sqrt(2.0))
        self.assertAlmostEqual(r["ratio"], 0.5)
        self.assertEqual(r["means_a"], [1.0])

    def test_mismatched_or_non_finite_images_are_refused(self):
        with self.assertRaises(ValueError):
            pt.verdict([[1.0]] * 3, [[1.0]] * 3, [[1.0]] * 3, [[1.0]] * 2)
        with self.assertRaises(ValueError):
            pt.verdict([[math.nan]] * 2, [[1.0]] * 2, [[1.0]] * 2, [[1.0]] * 2)


@unittest.skipUnless(HAVE_MITSUBA, "Mitsuba 3 / numpy not installed: pip install mitsuba numpy")
class Translation(unittest.TestCase):
    def scene(self, objects, lights=None):
        s = {"camera": {"position": [3000, 1, -4], "look_at": [3000, 0.5, 0], "vfov_deg": 40},
             "objects": objects, "render": {"integrator": "path", "max_distance": 50}}
        if lights is not None:
            s["lights"] = lights
        return s

    def test_planes_cylinders_mirrors_and_meshes_are_mapped_in_render_space(self):
        s = self.scene(
            [{"shape": {"plane": {}}, "material": {"color": [0.5, 0.5, 0.5]}},
             {"shape": {"union": {"children": [
                 {"shape": {"cylinder": {"radius": 0.3, "height": 1}},
                  "transform": {"translate": [3000, 0.5, 0]}},
                 {"shape": {"triangle": {"vertices": [[2999, 0, 1], [3001, 0, 1], [3000, 1, 1]]}}}]}},
              "material": {"color": [0.2, 0.4, 0.6], "reflectivity": 0.25}},
             {"shape": {"mesh": {"path": "meshes/bunny.obj"}}, "transform": {"translate": [3001, 0, 0], "scale": 0.2}}],
            [{"sphere_light": {"position": [3000, 3, -1], "radius": 0.2, "intensity": 5}}])
        d = pt.mitsuba_scene(mi, s, os.path.join(REPO, "scenes"), 8, 1, 1)
        self.assertEqual(d["light0"]["center"], [0.0, 2.0, 3.0])
        shapes = [v for k, v in d.items() if k.startswith("shape_")]
        kinds = [v["type"] if isinstance(v, dict) else "mesh" for v in shapes]
        self.assertEqual(kinds, ["rectangle", "cylinder", "disk", "disk", "mesh", "obj"])
        # The inherited mirror material: a two-sided blend of diffuse and a perfect mirror.
        blend = shapes[1]["bsdf"]["bsdf"]
        self.assertEqual((shapes[1]["bsdf"]["type"], blend["type"], blend["weight"]),
                         ("twosided", "blendbsdf", 0.25))
        self.assertEqual(blend["bsdf_1"], {"type": "conductor", "material": "none"})
        self.assertEqual(shapes[5]["bsdf"]["bsdf"]["type"], "diffuse")
        scene = mi.load_dict(d)
        self.assertEqual(len(scene.shapes()), 7)

    def test_csg_and_unshadowed_lights_are_declined(self):
        import crosscheck_mitsuba as cm

        s = self.scene([{"shape": {"subtraction": {"children": []}}}], [])
        with self.assertRaises(cm.Unsupported):
            pt.mitsuba_scene(mi, s, REPO, 8, 1, 1)
        s = self.scene([], [{"point": {"position": [0, 1, 0], "intensity": 1, "casts_shadows": False}}])
        with self.assertRaises(ValueError):
            pt.mitsuba_scene(mi, s, REPO, 8, 1, 1)


if __name__ == "__main__":
    unittest.main()
