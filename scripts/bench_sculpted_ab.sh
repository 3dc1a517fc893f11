#!/bin/sh
# Interleaved A/B of the sdf backend on the sculpted molecules: binary A (e.g. main's release
# build) against binary B (this branch's), alternating processes round by round, and B with
# prune_depth=0 (the per-bundle culling instead of pruning per region). Prints one line per
# render: label, scene, render ms, mean steps, rays. Reproduces docs/decisions' pruning record.
# Usage: scripts/bench_sculpted_ab.sh A_BIN B_BIN [ROUNDS] [THREADS]
set -eu
A=$1; B=$2; ROUNDS=${3:-3}; THREADS=${4:-1}
OUT=${TMPDIR:-/tmp}/sculpted_ab.png
run() {
  label=$1; bin=$2; scene=$3; shift 3
  "$bin" render "$scene" -b sdf --threads "$THREADS" --out "$OUT" --force "$@" |
    awk -v l="$label" -v s="$(basename "$scene" .json)" '
      /render [0-9.]+ ms/ { for (i = 1; i <= NF; i++) { if ($i == "render") ms = $(i + 1); if ($i ~ /^\(/ && $(i + 1) == "rays),") rays = substr($i, 2) } }
      /sdf steps: mean/ { gsub(",", "", $4); steps = $4 }
      END { printf "%s %s render_ms %s mean_steps %s rays %s ns_per_step %.1f\n", l, s, ms, steps, rays, ms * 1e6 / (steps * rays) }'
}
uptime
for r in $(seq 1 "$ROUNDS"); do
  for n in 10 100 1000 10000; do
    s=scenes/generated/sculpted/molecule_$n.json
    run A "$A" "$s"
    run B "$B" "$s"
    run B-culled "$B" "$s" --opt prune_depth=0
  done
done
uptime
