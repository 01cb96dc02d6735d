#!/usr/bin/env bash
# The Python package's tests: builds the abi3 wheel with `maturin build --release`, installs it
# with pytest and mypy in a fresh virtual environment (binary packages only: the install uses no
# Rust toolchain) and runs python/tests, which compare the package with bop_toolkit's reference
# scores and with the service's `poseboard` command. POSEBOARD_BIN names that command; after
# `cargo test --workspace`, pass POSEBOARD_BIN=target/debug/poseboard to reuse its build, since a
# `cargo build -p server` here would resolve other features and rebuild. Unset, it is built here.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
work="$root/target/python"
python="${PYTHON:-python3}"

# Build tools live in a venv of their own, kept between runs.
if [ ! -x "$work/tools/bin/maturin" ]; then
  "$python" -m venv "$work/tools"
  "$work/tools/bin/pip" install --quiet --disable-pip-version-check 'maturin>=1.9,<2'
fi

rm -rf "$work/wheels"
"$work/tools/bin/maturin" build --release --locked --quiet \
  --manifest-path "$root/python/Cargo.toml" --out "$work/wheels" --interpreter "$python"
wheel="$(ls "$work"/wheels/poseboard-*.whl)"
echo "wheel: $(basename "$wheel") ($(du -k "$wheel" | cut -f1) KiB)"

if [ -z "${POSEBOARD_BIN:-}" ]; then
  cargo build --locked --quiet -p server --bin poseboard --manifest-path "$root/Cargo.toml"
  export POSEBOARD_BIN="$root/target/debug/poseboard"
fi

rm -rf "$work/venv"
"$python" -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet --disable-pip-version-check --only-binary=:all: "$wheel" pytest mypy
cd "$root/python/tests"
PATH="$work/venv/bin:$PATH" "$work/venv/bin/python" -m pytest -q -p no:cacheprovider "$@"
