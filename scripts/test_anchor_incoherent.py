#!/usr/bin/env python3
"""Tests of scripts/anchor_incoherent.py, the incoherent rays of the Embree anchor:
`python3 -m unittest scripts/test_anchor_incoherent.py` (skipped without numpy; the anchor's
environment has it: ~/.cache/marchmesh/embree-venv/bin/python -m unittest ...).
"""

import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

try:
    import numpy as np

    import anchor_incoherent as ai

    HAVE_NUMPY = True
except ImportError:
    HAVE_NUMPY = False


def flat_scene(n_rays=400, seed=7):
    """A camera at the origin looking down +z at two triangles forming the square
    |x|, |y| <= 4 on the plane z = 5, and `n_rays` rays into it (some miss)."""
    rng = np.random.default_rng(seed)
    tris = np.array(
        [
            [[-4, -4, 5], [4, -4, 5], [4, 4, 5]],
            [[-4, -4, 5], [4, 4, 5], [-4, 4, 5]],
        ],
        dtype=np.float32,
    )
    d = np.column_stack([rng.uniform(-1.2, 1.2, n_rays), rng.uniform(-1.2, 1.2, n_rays),
                         np.ones(n_rays)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = np.zeros((n_rays, 6), dtype=np.float32)
    rays[:, 3:] = d
    t = (5.0 / rays[:, 5]).astype(np.float32)
    p = rays[:, 3:] * t[:, None]
    inside = (np.abs(p[:, 0]) <= 4) & (np.abs(p[:, 1]) <= 4)
    t = np.where(inside, t, np.inf).astype(np.float32)
    prim = np.where(inside, np.where(p[:, 1] <= p[:, 0], 0, 1), 0xFFFFFFFF).astype(np.uint32)
    return rays, t, prim, tris


@unittest.skipUnless(HAVE_NUMPY, "numpy is not installed")
class IncoherentRays(unittest.TestCase):
    def test_the_basis_is_orthonormal_for_every_normal(self):
        rng = np.random.default_rng(1)
        n = rng.normal(size=(1000, 3))
        n = np.vstack([n, [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1e-9, -1]]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        t, b = ai.orthonormal_basis(n)
        for a, c in ((t, b), (t, n), (b, n)):
            self.assertLess(np.abs(np.sum(a * c, axis=1)).max(), 1e-12)
        for a in (t, b):
            self.assertLess(np.abs(np.linalg.norm(a, axis=1) - 1).max(), 1e-12)

    def test_cosine_directions_lie_in_the_hemisphere_with_a_cosine_density(self):
        rng = np.random.default_rng(2)
        n = np.tile([[0.0, 0.6, -0.8]], (200_000, 1))
        d = ai.cosine_directions(n, rng.random(len(n)), rng.random(len(n)))
        cos = np.sum(d * n, axis=1)
        self.assertLess(np.abs(np.linalg.norm(d, axis=1) - 1).max(), 1e-12)
        self.assertGreaterEqual(cos.min(), 0.0)
        # Cosine-weighted: cos^2 is uniform on [0, 1], so E[cos] = 2/3 and E[cos^2] = 1/2.
        self.assertAlmostEqual(cos.mean(), 2 / 3, delta=0.005)
        self.assertAlmostEqual((cos**2).mean(), 0.5, delta=0.005)

    def test_rays_leave_each_hit_into_the_camera_side_hemisphere(self):
        rays, t, prim, tris = flat_scene()
        out = ai.incoherent_rays(rays, t, prim, tris, seed=3, ao_distance=0.5, per_hit=2)
        hits = int(np.isfinite(t).sum())
        self.assertGreater(hits, 0)
        self.assertLess(hits, len(t))
        for kind, tmax in (("ao", 0.5), ("bounce", np.inf)):
            r = out[kind]
            self.assertEqual(r.dtype, np.float32)
            self.assertEqual(r.shape, (2 * hits, 7))
            # The plane faces the camera: the normal is -z, origins just in front of z = 5.
            self.assertTrue((r[:, 5] <= 0).all(), kind)
            self.assertTrue((r[:, 2] < 5).all() and (r[:, 2] > 4.99).all(), kind)
            self.assertTrue((r[:, 6] == np.float32(tmax)).all(), kind)
            self.assertLess(np.abs(np.linalg.norm(r[:, 3:6], axis=1) - 1).max(), 1e-6)
        # A hit's rays are consecutive and share their origin.
        self.assertTrue((out["ao"][0::2, :3] == out["ao"][1::2, :3]).all())

    def test_the_offset_follows_the_integrators_rule(self):
        rays, t, prim, tris = flat_scene()
        origins, normals = ai.surface_points(rays, t, prim, tris, offset=1e-3)
        hit = np.isfinite(t)
        p = rays[hit, 3:].astype(np.float64) * t[hit, None]
        np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (len(p), 1)))
        np.testing.assert_allclose(origins[:, 2], 5 - 1e-3 * np.linalg.norm(p, axis=1))

    def test_the_seed_reproduces_the_rays_and_another_seed_changes_them(self):
        rays, t, prim, tris = flat_scene()
        a = ai.incoherent_rays(rays, t, prim, tris, seed=11, ao_distance=1.0)
        b = ai.incoherent_rays(rays, t, prim, tris, seed=11, ao_distance=1.0)
        c = ai.incoherent_rays(rays, t, prim, tris, seed=12, ao_distance=1.0)
        for kind in ("ao", "bounce"):
            self.assertEqual(a[kind].tobytes(), b[kind].tobytes())
            self.assertNotEqual(a[kind][:, 3:6].tobytes(), c[kind][:, 3:6].tobytes())
        # AO and bounce directions are separate draws.
        self.assertNotEqual(a["ao"][:, 3:6].tobytes(), a["bounce"][:, 3:6].tobytes())

    def test_shadow_rays_end_just_short_of_a_point_on_the_light(self):
        rays, t, prim, tris = flat_scene()
        # A light facing the plane's lit side (z < 5, where the camera is).
        light = (np.array([-1.0, -1.0, 2.0]), np.array([2.0, 0.0, 0.0]),
                 np.array([0.0, 2.0, 0.0]))
        out = ai.incoherent_rays(rays, t, prim, tris, seed=5, ao_distance=1.0, light=light)
        s = out["shadow"]
        hits = int(np.isfinite(t).sum())
        self.assertEqual(s.shape, (hits, 7))  # every hit sees the light in front of it
        _, _, points = ai.surface_frames(rays, t, prim, tris)
        end = points + s[:, 3:6].astype(np.float64) * (
            s[:, 6:7] + ai.RAY_OFFSET * np.linalg.norm(points, axis=1, keepdims=True)
        )
        np.testing.assert_allclose(end[:, 2], 2.0, atol=1e-4)
        self.assertTrue((np.abs(end[:, :2]) <= 1.0 + 1e-4).all())
        # The light is drawn after the other kinds: AO and bounce rays are the same without it.
        plain = ai.incoherent_rays(rays, t, prim, tris, seed=5, ao_distance=1.0)
        for kind in ("ao", "bounce"):
            self.assertEqual(plain[kind].tobytes(), out[kind].tobytes())
        self.assertNotIn("shadow", plain)

    def test_no_shadow_ray_leaves_towards_a_light_behind_the_surface(self):
        rays, t, prim, tris = flat_scene()
        behind = (np.array([-1.0, -1.0, 8.0]), np.array([2.0, 0.0, 0.0]),
                  np.array([0.0, 2.0, 0.0]))
        out = ai.incoherent_rays(rays, t, prim, tris, seed=5, ao_distance=1.0, light=behind)
        self.assertEqual(len(out["shadow"]), 0)

    def test_no_shadow_ray_leaves_from_behind_the_light(self):
        rays, t, prim, tris = flat_scene()
        # The light between the camera and the plane, but emitting towards the camera (-z):
        # the plane (z = 5) lies behind it.
        away = (np.array([-1.0, -1.0, 2.0]), np.array([0.0, 2.0, 0.0]),
                np.array([2.0, 0.0, 0.0]))
        out = ai.incoherent_rays(rays, t, prim, tris, seed=5, ao_distance=1.0, light=away)
        self.assertEqual(len(out["shadow"]), 0)

    def test_the_light_sits_centred_above_the_box(self):
        corner, u, v = ai.light_above([0, 0, 0], [2, 1, 2], size=0.5, height=1.0)
        diag = 3.0
        centre = corner + (u + v) / 2
        np.testing.assert_allclose(centre, [1.0, 1.0 + diag, 1.0])
        np.testing.assert_allclose([np.linalg.norm(u), np.linalg.norm(v)], [1.5, 1.5])
        self.assertLess(np.cross(u, v)[1], 0.0)  # it emits downwards
        corner, u, v = ai.light_above([0, 0, 0], [2, 1, 2], height=-0.01)
        self.assertAlmostEqual((corner + (u + v) / 2)[1], 1.0 - 0.03)  # under the ceiling

    def test_the_box_encloses_the_mesh_open_at_the_front(self):
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            src, dst = os.path.join(d, "m.obj"), os.path.join(d, "b.obj")
            with open(src, "w") as f:
                f.write("v 0 0 0\nv 2 0 0\nv 0 1 0.5\nf 1 2 3\n")
            self.assertEqual(ai.boxed_obj(src, dst, margin=0.25), 10)
            with open(dst) as f:
                lines = f.read().splitlines()
        verts = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln[:2] == "v "])
        faces = [[int(x) for x in ln.split()[1:]] for ln in lines if ln[:2] == "f "]
        self.assertEqual(faces[0], [1, 2, 3])  # the mesh's own face comes first, unchanged
        self.assertEqual(len(verts), 3 + 8)
        walls = np.array([verts[np.array(f) - 1] for f in faces[1:]])
        lo, hi = walls.reshape(-1, 3).min(axis=0), walls.reshape(-1, 3).max(axis=0)
        np.testing.assert_allclose(hi - lo, 3.0)  # largest extent 2, times 1.5
        self.assertLess(lo[1], 0.0)  # the floor just below the mesh
        np.testing.assert_allclose([(lo[0] + hi[0]) / 2, (lo[2] + hi[2]) / 2], [1.0, 0.25])
        # No wall lies in the front plane z = lo.z: every triangle touching it spans z.
        front = [w for w in walls if np.allclose(w[:, 2], lo[2])]
        self.assertEqual(front, [])

    def test_bad_arguments_are_refused(self):
        rays, t, prim, tris = flat_scene()
        with self.assertRaises(ValueError):
            ai.incoherent_rays(rays, t, prim, tris, seed=1, ao_distance=0.0)
        with self.assertRaises(ValueError):
            ai.incoherent_rays(rays, t, prim, tris, seed=1, ao_distance=1.0, per_hit=0)


if __name__ == "__main__":
    unittest.main()
