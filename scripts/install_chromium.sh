#!/usr/bin/env bash
# Installs Chromium (Debian/Ubuntu apt package), which the headless-browser test of report.html
# (crates/cli/tests/report_html.rs) needs; without it that test skips its browser part.
# Uses sudo when not run as root. Idempotent: does nothing if chromium is already on PATH.
set -euo pipefail

for name in chromium chromium-browser; do
    if command -v "$name" >/dev/null 2>&1; then
        echo "install_chromium: $(command -v "$name") already installed"
        exit 0
    fi
done
if ! command -v apt-get >/dev/null 2>&1; then
    echo "install_chromium: apt-get not found; install Chromium with your package manager" >&2
    exit 1
fi
sudo=()
if [ "$(id -u)" -ne 0 ]; then
    sudo=(sudo)
fi
export DEBIAN_FRONTEND=noninteractive
# Debian calls the package chromium; Ubuntu's chromium-browser is a transitional package.
# No recommended packages and no kept .deb files: CI machines may be short of disk.
install=("${sudo[@]}" apt-get install -y --no-install-recommends)
if ! "${install[@]}" chromium; then
    "${sudo[@]}" apt-get update
    "${install[@]}" chromium || "${install[@]}" chromium-browser
fi
"${sudo[@]}" apt-get clean || true
command -v chromium || command -v chromium-browser
