#!/usr/bin/env bash
# Every check poseboard has, the way CI runs them: formatting, lints, the Rust tests (against
# real SQLite and PostgreSQL: POSEBOARD_TEST_POSTGRES, default
# postgres://postgres@127.0.0.1:5432/test), and the Python package built, installed in a fresh
# virtual environment and tested against the same reference scores.
set -euo pipefail
cd "$(dirname "$0")/.."

cargo fmt --all --check
cargo clippy --workspace --all-targets --locked -- -D warnings
cargo test --workspace --locked
POSEBOARD_BIN="$PWD/target/debug/poseboard" bash python/tests/run.sh
