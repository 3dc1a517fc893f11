#!/usr/bin/env bash
# The fidget anchor (issue 14): builds crates/anchor-fidget (its own workspace, excluded from
# the root build) in release mode and runs it on the committed anchor scenes: marchmesh's sdf
# backend and fidget 0.4 on the same camera rays, interleaved, 1 thread, depth errors against
# the exact reference.
#
#   scripts/anchor_fidget.sh [extra anchor-fidget flags, e.g. --threads 2 --repeats 5]
#
# Writes into bench-results/anchors/:
#   fidget-<UTC stamp>.json        every scene at fidget's default depth (512 voxels a column)
#   fidget-<UTC stamp>-depth.json  seed-slab and sphere at 2048 and 8192 voxels a column
#   fidget-<UTC stamp>.md          both tables
# (a suffix -2, -3, ... when that name is taken) and prints the load average at start and end.
# Temporary files go to a private folder removed at exit. CARGO_TARGET_DIR is honoured
# (default: crates/anchor-fidget/target).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/anchor_common.sh
. "$root/scripts/anchor_common.sh"
crate="$root/crates/anchor-fidget"
target="${CARGO_TARGET_DIR:-$crate/target}"
# ANCHOR_OUT_DIR: where scripts/anchor.sh files them (default bench-results/anchors).
out="${ANCHOR_OUT_DIR:-$root/bench-results/anchors}"
anchor_private_tmp

echo "load at start: $(uptime)"
# Not --locked: the committed Cargo.lock pins fidget; a dependency added to a marchmesh crate
# since then is added to it rather than failing the build.
(cd "$crate" && CARGO_TARGET_DIR="$target" cargo build --release --quiet)
mkdir -p "$out"
base="$(anchor_reserve "$out" fidget)"
stamp="${base##*/fidget-}"
bin="$target/release/anchor-fidget"
# Scene paths in the results are relative to the repository root.
cd "$root"
s=crates/anchor-fidget/scenes
"$bin" "$s/seed-slab.json" "$s/sphere.json" "$s/spheres-1.json" "$s/spheres-10.json" \
    "$s/spheres-100.json" "$s/spheres-1000.json" \
    --json "$base.json" --markdown "$anchor_tmp/main.md" "$@"
echo "load between runs: $(uptime)"
# What fidget's depth resolution costs: its error is one voxel's quantisation.
"$bin" "$s/seed-slab.json" "$s/sphere.json" --depth 2048,8192 \
    --json "$base-depth.json" --markdown "$anchor_tmp/depth.md" "$@"
{
    echo "# fidget anchor, $stamp"
    echo
    echo "Command: scripts/anchor_fidget.sh $*"
    echo
    echo "## All scenes, fidget at 512 voxels a column"
    echo
    cat "$anchor_tmp/main.md"
    echo
    echo "## Depth resolution (${base##*/}-depth.json)"
    echo
    cat "$anchor_tmp/depth.md"
} >>"$base.md"
echo "load at end: $(uptime)"
echo "wrote $base.json, $base-depth.json and $base.md"
