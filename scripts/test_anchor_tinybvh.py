#!/usr/bin/env python3
"""Tests of scripts/anchor_tinybvh.py's own logic, the tinybvh anchor's parsing, ratios and
header lookup: `python3 -m unittest scripts/test_anchor_tinybvh.py` (the standard library
only: neither numpy, Embree nor tinybvh is needed; the git test skips without git).
"""

import os
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import anchor_tinybvh as at  # noqa: E402  (the folder of this script, added above)


class TraceOutput(unittest.TestCase):
    def test_a_build_line_then_one_rate_per_pass(self):
        p = at.parse_trace_output("build 0.012500 0.024000 1234\n10.5 42\n11.0 42\n9.5 42\n")
        self.assertEqual(p["build_wall_s"], 0.0125)
        self.assertEqual(p["build_cpu_s"], 0.024)
        self.assertEqual(p["bytes"], 1234)
        self.assertEqual(p["rates"], [10.5, 11.0, 9.5])
        self.assertEqual(p["count"], 42)

    def test_malformed_output_is_refused(self):
        for text in (
            "",
            "10.5 42\n",  # no build line
            "build 0.1 0.1\n10.5 42\n",  # build line short
            "build 0.1 0.1 7\n",  # no passes
            "build 0.1 0.1 7\n10.5\n",  # a pass without its count
            "build 0.1 0.1 7\n0 42\n",  # a rate of zero
            "build 0.1 0.1 7\ninf 42\n",
            "build 0.1 0.1 7\n10.5 42\n10.4 41\n",  # passes disagree on the count
        ):
            with self.subTest(text=text), self.assertRaises(ValueError):
                at.parse_trace_output(text)

    def test_anchor_rays_pairs(self):
        self.assertEqual(at.parse_pairs("7.5 100\n8.5 100\n"), ([7.5, 8.5], 100))
        for text in ("", "7.5\n", "7.5 100 8.5\n"):
            with self.subTest(text=text), self.assertRaises(ValueError):
                at.parse_pairs(text)


class Ratios(unittest.TestCase):
    def test_odd_rounds_reverse_the_order(self):
        self.assertEqual(at.round_order(["a", "b", "c"], 0), ["a", "b", "c"])
        self.assertEqual(at.round_order(["a", "b", "c"], 1), ["c", "b", "a"])
        self.assertEqual(at.round_order(["a", "b", "c"], 2), ["a", "b", "c"])

    def test_the_ratio_is_the_median_of_per_round_ratios(self):
        # Per round 2.0, 0.5, 1.0: median 1.0 (the ratio of medians would be 6 / 4 = 1.5).
        self.assertEqual(at.ratio([4.0, 1.0, 6.0], [2.0, 2.0, 6.0]), 1.0)
        with self.assertRaises(ValueError):
            at.ratio([1.0], [1.0, 2.0])

    def test_the_fastest_peer_is_taken_round_by_round(self):
        ours = [10.0, 10.0, 10.0]
        peers = {"embree1": [8.0, 12.0, 9.0], "tinybvh-bvh8": [9.0, 11.0, 10.0]}
        r, wins = at.ratio_to_fastest(ours, peers)
        # Per round 10/9, 10/12, 10/10.
        self.assertAlmostEqual(r, 1.0)
        self.assertEqual(wins, {"embree1": 1, "tinybvh-bvh8": 2})
        with self.assertRaises(ValueError):
            at.ratio_to_fastest(ours, {})

    def test_each_kind_has_its_marchmesh_tracers(self):
        self.assertEqual(at.mesh_tracers("camera"), ["wide1", "wide4x2"])
        for kind in ("ao", "bounce", "shadow"):
            self.assertEqual(at.mesh_tracers(kind), ["wide"])
        self.assertEqual(set(at.KINDS), {"camera", "ao", "bounce", "shadow"})


HEADER_TEXT = (
    "// tiny\n#define TINY_BVH_VERSION_MAJOR\t1\n#define TINY_BVH_VERSION_MINOR\t6\n"
    "#define TINY_BVH_VERSION_SUB\t7\n#define TINY_BVH_CACHE_VERSION\t166\n"
)


class Header(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp()
        self.addCleanup(shutil.rmtree, self.tmp)

    def test_the_version_comes_from_the_defines(self):
        self.assertEqual(at.header_version(HEADER_TEXT), "1.6.7")
        self.assertIsNone(at.header_version("#define TINY_BVH_VERSION_MAJOR 1\n"))

    def test_tinybvh_dir_must_hold_the_header(self):
        env = {"TINYBVH_DIR": self.tmp}
        with self.assertRaises(at.SetupError) as e:
            at.find_header(self.tmp, env)
        self.assertIn("TINYBVH_DIR", str(e.exception))
        self.assertIn("tiny_bvh.h", str(e.exception))
        path = os.path.join(self.tmp, "tiny_bvh.h")
        with open(path, "w") as f:
            f.write(HEADER_TEXT)
        self.assertEqual(at.find_header(self.tmp, env), (path, path, None))

    def test_without_either_place_the_message_names_both(self):
        missing = os.path.join(self.tmp, "no-such-mirror")
        with self.assertRaises(at.SetupError) as e:
            at.find_header(self.tmp, {"TINYBVH_GIT_DIR": missing})
        self.assertIn("TINYBVH_DIR", str(e.exception))
        self.assertIn(missing, str(e.exception))

    @unittest.skipUnless(shutil.which("git"), "git is not installed")
    def test_the_header_is_read_from_a_git_directory(self):
        work = os.path.join(self.tmp, "src")
        os.mkdir(work)
        with open(os.path.join(work, "tiny_bvh.h"), "w") as f:
            f.write(HEADER_TEXT)
        git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
        # Quiet: git's hints would land in the middle of unittest's `name ... ok` lines.
        for cmd in (["init", "-q", work], ["-C", work, "add", "tiny_bvh.h"],
                    ["-C", work, "commit", "-q", "-m", "h"]):
            subprocess.run([*git, *cmd], check=True, capture_output=True)
        out = os.path.join(self.tmp, "out")
        os.mkdir(out)
        path, source, commit = at.find_header(out, {"TINYBVH_GIT_DIR": os.path.join(work, ".git")})
        self.assertEqual(path, os.path.join(out, "tiny_bvh.h"))
        with open(path) as f:
            self.assertEqual(f.read(), HEADER_TEXT)
        self.assertIn("HEAD:tiny_bvh.h", source)
        self.assertRegex(commit, r"^[0-9a-f]{40}$")


if __name__ == "__main__":
    unittest.main()
