#!/usr/bin/env bash
# The Embree anchor (issue 16): Embree 4's single-ray rtcIntersect1 (the embreex package) and
# the mesh backend's tracers on the exact same camera rays of each committed mesh, interleaved,
# 1 thread (scripts/anchor_embree.py does the timing; this wrapper picks the meshes, sets up
# the Python environment and files the results). Then incoherent rays drawn from those camera
# rays' hits (issue 42: ambient-occlusion rays as occlusion queries, diffuse bounce rays as
# closest-hit queries; scripts/anchor_incoherent.py) on Embree's rtcOccluded1 / rtcIntersect1
# and 8-wide calls and the mesh backend's batch calls; --no-incoherent skips them.
#
#   scripts/anchor_embree.sh [--large] [extra anchor_embree.py flags, e.g. --rounds 5 --repeats 9]
#
# --large adds the full Stanford dragon (871k triangles; scripts/fetch_dragon.sh, or
# ../shared/data/dragon_full.obj.gz when present). Writes into bench-results/anchors/:
#   embree-<UTC stamp>.json   every figure per round (read by `marchmesh bench --anchor` and
#                             `marchmesh findings --anchor`)
#   embree-<UTC stamp>.md     the printed tables
# (a suffix -2, -3, ... when that name is taken). The Python environment is EMBREE_VENV
# (default ~/.cache/marchmesh/embree-venv; one not owned by you or writable by others is
# refused), created with embreex and numpy from the Python package index when missing.
# Temporary files go to a private folder removed at exit. CARGO_TARGET_DIR is honoured.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/anchor_common.sh
. "$root/scripts/anchor_common.sh"
venv="$(anchor_venv embree-venv)"
# ANCHOR_OUT_DIR: where scripts/anchor.sh files them (default bench-results/anchors).
out="${ANCHOR_OUT_DIR:-$root/bench-results/anchors}"
anchor_private_tmp

# The command line as given (the shift below drops --large from "$@").
given="$*"
meshes=("$root/scenes/meshes/bunny.obj" "$root/scenes/meshes/dragon_res3.obj")
if [ "${1:-}" = "--large" ]; then
    shift
    dragon="${DRAGON_OBJ:-}"
    if [ -z "$dragon" ] || [ ! -s "$dragon" ]; then
        shared="$root/../shared/data/dragon_full.obj.gz"
        if [ -s "$shared" ]; then
            dragon="$anchor_tmp/dragon.obj"
            gunzip -c "$shared" >"$dragon"
        else
            echo "no full dragon at ${DRAGON_OBJ:-\$DRAGON_OBJ} or $shared: run scripts/fetch_dragon.sh and set DRAGON_OBJ" >&2
            exit 1
        fi
    fi
    meshes+=("$dragon")
fi

if [ ! -x "$venv/bin/python" ]; then
    mkdir -p -m 700 "$(dirname "$venv")"
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet embreex numpy
fi
(cd "$root" && cargo build --release --quiet -p marchmesh-mesh --example anchor_rays)
mkdir -p "$out"
base="$(anchor_reserve "$out" embree)"
stamp="${base##*/embree-}"
echo "load at start: $(uptime)"
"$venv/bin/python" "$root/scripts/anchor_embree.py" "${meshes[@]}" --bvh wide1,wide4x2 \
    --json "$base.json" "$@" | tee "$anchor_tmp/tables.md"
{
    echo "# Embree anchor, $stamp"
    echo
    echo "Command: scripts/anchor_embree.sh $given"
    echo
    echo '```'
    cat "$anchor_tmp/tables.md"
    echo '```'
} >>"$base.md"
echo "load at end: $(uptime)"
echo "wrote $base.json and .md"
