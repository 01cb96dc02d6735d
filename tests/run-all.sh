#!/usr/bin/env bash
# Every check poseboard has, the way CI runs them: formatting, lints, the Rust tests (against
# real SQLite and PostgreSQL: POSEBOARD_TEST_POSTGRES, default
# postgres://postgres@127.0.0.1:5432/test), the Python package built, installed in a fresh
# virtual environment and tested against the same reference scores, and every fuzz target run
# for 20 seconds (fuzz/smoke.sh: a crash, timeout or allocation past its bound fails).
set -euo pipefail
cd "$(dirname "$0")/.."

cargo fmt --all --check

# The lints and the test build are one compilation: clippy-driver compiles the workspace's own
# crates (it is rustc with clippy's lints added), so `cargo test` builds every target once,
# linted, where `cargo clippy` followed by `cargo test` compiled all dependencies twice (once
# for checking, once for building): on CI's 2 cores that second pass cost about ten minutes.
# Every target is built, benches included, as `cargo clippy --all-targets` checked them.
export RUSTC_WORKSPACE_WRAPPER="${CLIPPY_DRIVER:-$(command -v clippy-driver)}"
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
cargo test --workspace --all-targets --locked --no-run
cargo test --workspace --locked
unset RUSTC_WORKSPACE_WRAPPER CLIPPY_ARGS

POSEBOARD_BIN="$PWD/target/debug/poseboard" bash python/tests/run.sh

bash fuzz/smoke.sh
