#!/usr/bin/env bash
# Runs a marchmesh benchmark suite as a Slurm job array, one shard per task, then merges the
# shards into one run folder.
#
#   scripts/slurm_bench.sh [--wait] [--rerun-failed] SUITE SHARDS OUT [extra bench flags...]
#   e.g. scripts/slurm_bench.sh scaling 16 /scratch/$USER/marchmesh
#
# Layout under OUT: shards/K/<run-id>/ (shard K's run), shards/K.ok or shards/K.failed (its
# outcome), logs/ (Slurm's logs), merged/ (the merged run, written by the merge job), and
# attempts/ (earlier shard and merged folders moved aside by --rerun-failed: nothing is deleted).
#
# --wait          block until the merge job ends and exit with its status (0: every shard ran
#                 and the merge holds every configuration).
# --rerun-failed  submit only the shards of OUT that have no K.ok (failed, cancelled, or never
#                 ran), then merge again. SUITE and SHARDS must be the ones of the first run.
#
# Every task runs the very build that was submitted: its SHA-256 is recorded at submission and
# a node whose binary is missing or differs refuses its shard before any work. Build once on a
# shared file system first (cargo build --release --locked). MARCHMESH_BIN names another binary
# (default: target/release/marchmesh of this checkout). Rows keep the host name of the node
# that measured them; the merged summary compares speed only within one node.
# Pass sbatch options (partition, time, account) through SBATCH_* environment variables, e.g.
# SBATCH_PARTITION=gpu SBATCH_TIMELIMIT=2:00:00.
set -euo pipefail

usage() {
  echo "usage: $0 [--wait] [--rerun-failed] SUITE SHARDS OUT [extra bench flags...]" >&2
  exit 2
}
die() { echo "error: $*" >&2; exit 1; }

wait_for_merge=0 rerun=0
while [ $# -gt 0 ]; do
  case $1 in
    --wait) wait_for_merge=1; shift ;;
    --rerun-failed) rerun=1; shift ;;
    --help|-h) usage ;;
    --) shift; break ;;
    -*) echo "error: unknown option $1" >&2; usage ;;
    *) break ;;
  esac
done
[ $# -ge 3 ] || usage
suite=$1 shards=$2 out=$3
shift 3
case $shards in (''|*[!0-9]*|0*) die "SHARDS must be a positive integer (got '$shards')";; esac
[ "${#shards}" -le 5 ] || die "SHARDS must be at most 99999 (got $shards)"

command -v sbatch >/dev/null 2>&1 \
  || die "sbatch is not on PATH: this script needs a Slurm cluster (one node for testing: scripts/slurm_local.sh start); on one machine use GNU parallel (see the README)"

root=$(cd "$(dirname "$0")/.." && pwd)
bin=${MARCHMESH_BIN:-$root/target/release/marchmesh}
[ -f "$bin" ] && [ -x "$bin" ] || die "$bin is not built (cargo build --release --locked, or set MARCHMESH_BIN)"
case $bin in (/*) ;; (*) bin="$PWD/$bin" ;; esac
sha=$(sha256sum "$bin" | cut -d' ' -f1)
# The suite as the bench command will see it: a path is made absolute (tasks run from $root).
if [ -e "$suite" ]; then
  suite=$(cd "$(dirname "$suite")" && pwd)/$(basename "$suite")
fi

mkdir -p "$out"
out=$(cd "$out" && pwd)
mkdir -p "$out/shards" "$out/logs" "$out/attempts"
stamp=$(date -u +%Y%m%dT%H%M%SZ)

if [ "$rerun" = 1 ]; then
  [ -f "$out/submitted" ] || die "$out holds no earlier submission (no $out/submitted)"
  read -r old_suite_q old_shards <"$out/submitted.args" || die "$out/submitted.args is unreadable"
  [ "$old_shards" = "$shards" ] || die "$out was submitted with $old_shards shards, not $shards"
  [ "$old_suite_q" = "$(printf %q "$suite")" ] || die "$out was submitted for another suite"
  todo=()
  for k in $(seq 1 "$shards"); do
    [ -f "$out/shards/$k.ok" ] && continue
    todo+=("$k")
    # Move the failed attempt aside (never delete what a run left).
    if [ -e "$out/shards/$k" ]; then mv "$out/shards/$k" "$out/attempts/shard-$k-$stamp"; fi
    rm -f "$out/shards/$k.failed"
  done
  if [ ${#todo[@]} = 0 ]; then
    echo "every shard of $out has run; nothing to rerun"
    exit 0
  fi
  array=$(IFS=,; echo "${todo[*]}")
else
  [ ! -e "$out/submitted" ] || die "$out already holds a submission: use --rerun-failed to finish it, or another OUT"
  array="1-$shards"
  printf '%q %s\n' "$suite" "$shards" >"$out/submitted.args"
fi

extra=""
[ $# -gt 0 ] && extra=$(printf ' %q' "$@")
q() { printf %q "$1"; }

# One task: check the build, run shard K, record the outcome.
cat >"$out/task.sh" <<EOF
#!/usr/bin/env bash
set -uo pipefail
k=\${SLURM_ARRAY_TASK_ID:?not run by Slurm}
out=$(q "$out")
bin=$(q "$bin")
actual=\$(sha256sum "\$bin" 2>/dev/null | cut -d' ' -f1)
if [ "\$actual" != $(q "$sha") ]; then
  msg="node \$(hostname -s): \$bin is missing or is not the build that was submitted (sha256 \${actual:-none}, expected $sha); shard \$k refused"
  echo "error: \$msg" >&2
  echo "\$msg" >"\$out/shards/\$k.failed"
  exit 3
fi
mkdir -p "\$out/shards/\$k"
cd $(q "$root")
"\$bin" bench --suite $(q "$suite") --shard "\$k/$shards" --out "\$out/shards/\$k"$extra
rc=\$?
if [ \$rc = 0 ]; then
  touch "\$out/shards/\$k.ok"
else
  echo "bench exited with \$rc on \$(hostname -s)" >"\$out/shards/\$k.failed"
fi
exit \$rc
EOF

# The merge: every shard must have run; then marchmesh merge (which names missing
# configurations and exits nonzero on an incomplete merge).
cat >"$out/merge.sh" <<EOF
#!/usr/bin/env bash
set -uo pipefail
out=$(q "$out")
missing=()
for k in \$(seq 1 $shards); do
  [ -f "\$out/shards/\$k.ok" ] || missing+=("\$k")
done
if [ -e "\$out/merged" ]; then mv "\$out/merged" "\$out/attempts/merged-\$(date -u +%Y%m%dT%H%M%SZ)-\$\$"; fi
runs=()
for d in "\$out"/shards/*/*/; do
  [ -f "\$d/results.json" ] && runs+=("\$d")
done
rc=0
if [ \${#runs[@]} -gt 0 ]; then
  $(q "$bin") merge "\${runs[@]}" --out "\$out/merged" || rc=\$?
else
  echo "error: no shard produced a run folder" >&2
  rc=1
fi
if [ \${#missing[@]} -gt 0 ]; then
  echo "error: shard(s) \${missing[*]} of $shards did not finish (failed, cancelled or refused):" >&2
  for k in "\${missing[@]}"; do
    [ -f "\$out/shards/\$k.failed" ] && echo "  shard \$k: \$(cat "\$out/shards/\$k.failed")" >&2
  done
  echo "rerun only those: scripts/slurm_bench.sh --rerun-failed $(q "$suite") $shards $(q "$out")" >&2
  [ \$rc = 0 ] && rc=1
fi
exit \$rc
EOF
chmod +x "$out/task.sh" "$out/merge.sh"

array_job=$(sbatch --parsable --array="$array" --job-name="marchmesh-shard" \
  --exclusive --output="$out/logs/shard-%A_%a.log" "$out/task.sh") \
  || die "sbatch refused the shard array"
array_job=${array_job%%;*}
touch "$out/submitted"
echo "array job $array_job: shards $array of $shards"

merge_args=(--parsable --dependency="afterany:$array_job" --job-name="marchmesh-merge"
  --output="$out/logs/merge-%j.log")
if [ "$wait_for_merge" = 1 ]; then
  echo "merge job submitted; waiting for it (results in $out/merged)"
  set +e
  sbatch --wait "${merge_args[@]}" "$out/merge.sh" >/dev/null
  rc=$?
  set -e
  cat "$out"/logs/merge-*.log 2>/dev/null | tail -n 40 >&2 || true
  exit $rc
fi
merge_job=$(sbatch "${merge_args[@]}" "$out/merge.sh") || die "sbatch refused the merge job"
echo "merge job ${merge_job%%;*}: results in $out/merged"
