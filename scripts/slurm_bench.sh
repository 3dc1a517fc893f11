#!/usr/bin/env bash
# Runs a marchmesh benchmark suite as a Slurm job array, one shard per task, then merges the
# shards into one run folder.
#
#   scripts/slurm_bench.sh SUITE SHARDS OUT [extra bench flags...]
#   e.g. scripts/slurm_bench.sh scaling 16 /scratch/$USER/marchmesh
#
# Every task must run the same build (same commit: `marchmesh merge` refuses mixed commits).
# Build once on a shared file system first: cargo build --release. Rows keep the host name of
# the node that measured them; the merged summary compares speed only within one node.
# Set SBATCH flags (partition, time, cpus-per-task) through SBATCH_* environment variables or
# edit the two sbatch calls below.
set -euo pipefail
if [ $# -lt 3 ]; then
  echo "usage: $0 SUITE SHARDS OUT [extra bench flags...]" >&2
  exit 2
fi
suite=$1 shards=$2 out=$3
shift 3
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/target/release/marchmesh"
[ -x "$bin" ] || { echo "error: $bin not built (cargo build --release)" >&2; exit 1; }
case $shards in (''|*[!0-9]*|0) echo "error: SHARDS must be a positive integer" >&2; exit 2;; esac
mkdir -p "$out/shards"
extra=$(printf ' %q' "$@")

array_job=$(sbatch --parsable --array="1-$shards" --job-name="marchmesh-$suite" \
  --exclusive --output="$out/shards/slurm-%A_%a.log" \
  --wrap="cd $(printf %q "$root") && $(printf %q "$bin") bench --suite $(printf %q "$suite") --shard \${SLURM_ARRAY_TASK_ID}/$shards --out $(printf %q "$out/shards")$extra")

sbatch --parsable --dependency="afterany:$array_job" --job-name="marchmesh-$suite-merge" \
  --output="$out/merge-%j.log" \
  --wrap="cd $(printf %q "$root") && $(printf %q "$bin") merge $(printf %q "$out/shards")/*-*/ --out $(printf %q "$out/merged")"
echo "submitted array job $array_job ($shards shards) and its merge; results in $out/merged"
