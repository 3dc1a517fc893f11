#!/usr/bin/env bash
# Regenerates the report screenshots under docs/ (docs/guide.md shows them): a committed run's
# report regenerated in a scratch folder and photographed by headless Chromium at 1400 px.
# Usage: scripts/screenshots.sh [MARCHMESH_BIN] [RUN]   (defaults: target/release/marchmesh,
# the newest committed default run)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/marchmesh}
run=${2:-$(ls -d bench-results/*-default | tail -1)}
browser=$(command -v chromium || command -v chromium-browser) || {
  echo "error: Chromium is needed (bash scripts/install_chromium.sh)" >&2
  exit 1
}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir "$work/run"
cp "$run/results.json" "$work/run/"
[ -d "$run/images" ] && cp -r "$run/images" "$work/run/"
"$bin" report "$work/run"
"$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
  --screenshot="$work/report.png" --window-size=1400,1100 "file://$work/run/report.html" 2>/dev/null
plot=$(ls "$work"/run/plots/time_vs_error_*csg*.svg | head -1)
"$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
  --screenshot="$work/plot.png" --window-size=736,496 "file://$plot" 2>/dev/null
cp "$work/report.png" docs/report-1400.png
cp "$work/plot.png" docs/plot-time-vs-accuracy.png
echo "docs/report-1400.png, docs/plot-time-vs-accuracy.png from $run"
