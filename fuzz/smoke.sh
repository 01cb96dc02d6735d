#!/usr/bin/env bash
# Runs every fuzz target for a short while (20 s each by default; FUZZ_SECONDS to change it)
# from its seed corpus, within the bounds of bounds.sh, and fails on any crash, leak, timeout
# or out-of-memory, naming the target: part of the test command (tests/run-all.sh). See the README's
# Fuzzing section for its cost.
#
# The seeds in fuzz/corpus/<target> are read only: what the fuzzer finds goes to a temporary
# folder, so a run leaves the repository as it was (a crash is written to
# fuzz/artifacts/<target>/, and the failing target is named).
set -euo pipefail
cd "$(dirname "$0")"
source ./toolchain.sh
source ./bounds.sh

seconds="${FUZZ_SECONDS:-20}"

# One build of every target first, so that the timed runs below only fuzz. Debug assertions
# and overflow checks on: an overflow is a finding.
"${fuzz_cargo[@]}" fuzz build --debug-assertions

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
# The targets run side by side, one per core: each still fuzzes for its full `seconds`, and the
# smoke costs the test command a ninth of its length per core instead of all of it.
jobs="${FUZZ_JOBS:-$(nproc)}"
run_one() {
  local target="$1"
  fuzz_bounds "$target"
  mkdir -p "$work/$target"
  if "${fuzz_cargo[@]}" fuzz run --debug-assertions "$target" "$work/$target" "corpus/$target" $(ls -d "regressions/$target" 2>/dev/null) -- \
    -max_total_time="$seconds" "${bounds[@]}" -print_final_stats=1 >"$work/$target.log" 2>&1; then
    touch "$work/$target.passed"
  fi
}
running=0
for target in "${fuzz_targets[@]}"; do
  run_one "$target" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then
    wait -n || true
    running=$((running - 1))
  fi
done
wait
failed=0
for target in "${fuzz_targets[@]}"; do
  log="$work/$target.log"
  if [ ! -e "$work/$target.passed" ]; then
    tail -n 60 "$log" >&2
    echo "fuzz/smoke.sh: target $target failed (input kept in fuzz/artifacts/$target/)" >&2
    failed=$((failed + 1))
    continue
  fi
  runs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")"
  echo "fuzz $target: ${runs:-?} inputs in ${seconds} s, no crash"
done
echo "fuzz: $(( ${#fuzz_targets[@]} - failed )) passed, $failed failed"
[ "$failed" -eq 0 ]
