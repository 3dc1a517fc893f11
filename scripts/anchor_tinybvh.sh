#!/usr/bin/env bash
# The tinybvh anchor (issue 42, item 2): tinybvh's single-ray traversal (BVH8_CPU, BVH4_CPU;
# scripts/tinybvh_trace.cpp), Embree 4 (scripts/embree_trace.c) and the mesh backend on the
# same camera rays and incoherent rays (AO, bounce, area-light shadow) of each mesh, in
# interleaved rounds on thread CPU time, 1 thread (scripts/anchor_tinybvh.py does the timing;
# this wrapper picks the meshes, checks the Python environment and files the results).
#
#   scripts/anchor_tinybvh.sh [--large] [extra anchor_tinybvh.py flags, e.g. --rounds 7 --repeats 9]
#
# --large adds the full Stanford dragon (871k triangles; scripts/fetch_dragon.sh, or
# ../shared/data/dragon_full.obj.gz when present), as scripts/anchor_embree.sh does.
# tinybvh's header is found at run time, not vendored: $TINYBVH_DIR/tiny_bvh.h, else HEAD of
# the git directory $TINYBVH_GIT_DIR (default: the development machines' mirror of
# github.com/jbikker/tinybvh; see scripts/anchor_tinybvh.py); the run stops naming both when
# neither has it. Writes into bench-results/anchors/:
#   tinybvh-<UTC stamp>.json   every figure per round, with the load average
#   tinybvh-<UTC stamp>.md     the printed tables
# (a suffix -2, -3, ... when that name is taken). The Python environment is the Embree
# anchor's, EMBREE_VENV (default ~/.cache/marchmesh/embree-venv; one not owned by you or
# writable by others is refused), created with embreex and numpy when missing. Temporary
# files go to a private folder removed at exit. CARGO_TARGET_DIR is honoured.
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
base="$(anchor_reserve "$out" tinybvh)"
stamp="${base##*/tinybvh-}"
echo "load at start: $(uptime)"
if ! TMPDIR="$anchor_tmp" "$venv/bin/python" "$root/scripts/anchor_tinybvh.py" "${meshes[@]}" \
    --json "$base.json" "$@" | tee "$anchor_tmp/tables.md"; then
    rm -f "$base.md"
    echo "anchor_tinybvh.py failed: nothing filed" >&2
    exit 1
fi
{
    echo "# tinybvh anchor, $stamp"
    echo
    echo "Command: scripts/anchor_tinybvh.sh $given"
    echo
    echo '```'
    cat "$anchor_tmp/tables.md"
    echo '```'
} >>"$base.md"
echo "load at end: $(uptime)"
echo "wrote $base.json and .md"
