#!/usr/bin/env bash
# Runs every fuzz target for a short while (20 s each by default; FUZZ_SECONDS to change it)
# from its seed corpus, and fails on the first crash, leak, timeout or out-of-memory. Run by
# hand until its cost on CI is measured (see the README's Fuzzing section). Needs the nightly
# toolchain (libFuzzer's coverage instrumentation); installs cargo-fuzz when missing.
#
# The seeds in fuzz/corpus/<target> are read only: what the fuzzer finds goes to a temporary
# folder, so a run leaves the repository as it was (a crash is written to
# fuzz/artifacts/<target>/, and the failing target is named).
set -euo pipefail
cd "$(dirname "$0")"

seconds="${FUZZ_SECONDS:-20}"
targets=(bop_csv bop22_json ply depth_png depth_tiff dataset_json)

if ! cargo +nightly --version >/dev/null 2>&1; then
  echo "fuzz/smoke.sh: the nightly Rust toolchain is missing; the fuzz targets need it" \
    "(install it with \`rustup toolchain install nightly\`)" >&2
  exit 1
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
  cargo install --locked cargo-fuzz
fi

# One build of every target first, so that the timed runs below only fuzz.
cargo +nightly fuzz build

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for target in "${targets[@]}"; do
  mkdir -p "$work/$target"
  log="$work/$target.log"
  if ! cargo +nightly fuzz run "$target" "$work/$target" "corpus/$target" -- \
    -max_total_time="$seconds" -timeout=10 -print_final_stats=1 >"$log" 2>&1; then
    tail -n 60 "$log" >&2
    echo "fuzz/smoke.sh: target $target failed (input kept in fuzz/artifacts/$target/)" >&2
    exit 1
  fi
  runs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")"
  echo "fuzz $target: ${runs:-?} inputs in ${seconds} s, no crash"
done
