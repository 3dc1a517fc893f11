#!/usr/bin/env bash
# CI checks beyond the root workspace's build and tests (called by .ci/run):
#
# 1. The two crates with workspaces of their own type-check against their committed lock files
#    (`--locked`: a lock file that drifted from its manifest is an error, not a silent rewrite):
#    the fidget anchor (fidget and its JIT stay out of the root build) and the fuzz targets.
#    The fuzz targets need nightly and cargo-fuzz to run, but they compile on stable, which is
#    what this checks.
# 2. The field crate's optional cranelift JIT (cargo feature `jit`, off by default because
#    cranelift doubles the crate's cold build) type-checks with its tests, so it cannot rot.
# 3. The root workspace builds (libraries and the binary, debug) for a portable x86-64 target.
#    `.cargo/config.toml` builds for the host CPU (`target-cpu=native`); RUSTFLAGS replaces
#    that setting, so this catches code that only compiles with the host's target features
#    (the mesh backend's AVX and AVX-512 paths are chosen at run time and must compile without
#    them). A build, not a check: an intrinsic inlined into a function without its target
#    feature fails only in code generation. Tests and benches are type-checked natively by
#    clippy; building them again here would double the time for no other class of error.
#
# The two outside crates are `cargo check`ed only (no code generation, no linking). All output
# goes under target/ (target/extra for the two crates, target/portable for the portable build),
# so `rm -rf target` still removes everything and the main build's artifacts stay as they are.
set -euo pipefail
cd "$(dirname "$0")/.."

extra="$PWD/target/extra"

echo "== cargo check crates/anchor-fidget (own workspace, --locked)"
CARGO_TARGET_DIR="$extra" cargo check --manifest-path crates/anchor-fidget/Cargo.toml \
  --all-targets --locked

echo "== cargo check crates/fuzz (own workspace, --locked, stable)"
CARGO_TARGET_DIR="$extra" cargo check --manifest-path crates/fuzz/Cargo.toml \
  --all-targets --locked

echo "== cargo check the field crate's optional cranelift JIT (feature jit, off by default)"
cargo check -p marchmesh-field -p marchmesh-sdf --features marchmesh-sdf/jit --all-targets --locked

echo "== cargo build --workspace for a portable x86-64 target"
RUSTFLAGS="-C target-cpu=x86-64" CARGO_TARGET_DIR="$PWD/target/portable" \
  cargo build --workspace --locked
