#!/usr/bin/env bash
# The long campaign: every target for 10,000,000 inputs (FUZZ_RUNS to change it) within the
# bounds of bounds.sh, from its seeds and what earlier campaigns kept, one target after the
# other. Figures (inputs, seconds, inputs per second, corpus size, crashes) go to a table,
# FIGURES (default fuzz/campaign-figures.tsv), one line per target as it ends; each target's
# full log beside it. A target that fails is recorded and the campaign goes on: the input is
# in fuzz/artifacts/<target>/, to become a regression test once fixed.
#
#   nice -n 19 fuzz/campaign.sh                      # the README's figures
#   FUZZ_RUNS=100000 FIGURES=/tmp/f.tsv fuzz/campaign.sh bop_csv
#
# The corpus each target grows is kept in fuzz/campaign-corpus/<target> (not in git): a later
# campaign starts from it.
set -uo pipefail
cd "$(dirname "$0")"
source ./toolchain.sh
source ./bounds.sh

runs="${FUZZ_RUNS:-10000000}"
figures="${FIGURES:-$PWD/campaign-figures.tsv}"
logs="$(dirname "$figures")"
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${fuzz_targets[@]}")

"${fuzz_cargo[@]}" fuzz build --debug-assertions || exit 1

if [ ! -s "$figures" ]; then
  printf 'target\tinputs\tseconds\tinputs_per_s\tcorpus_files\tcorpus_bytes\tresult\tstarted_utc\tload_avg_1m\n' >"$figures"
fi
for target in "${targets[@]}"; do
  fuzz_bounds "$target" || continue
  corpus="campaign-corpus/$target"
  mkdir -p "$corpus"
  log="$logs/campaign-$target.log"
  started="$(date -u +%FT%TZ)"
  load="$(cut -d' ' -f1 /proc/loadavg)"
  begin="$(date +%s)"
  "${fuzz_cargo[@]}" fuzz run --debug-assertions "$target" "$corpus" "corpus/$target" $(ls -d "regressions/$target" 2>/dev/null) -- \
    -runs="$runs" "${bounds[@]}" -print_final_stats=1 >"$log" 2>&1
  status=$?
  seconds=$(( $(date +%s) - begin ))
  inputs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)"
  if [ "$status" -eq 0 ]; then
    result="no crash"
  else
    result="FAILED ($(grep -m1 -o 'ERROR: libFuzzer: [a-z-]*\|panicked at [^ ]*' "$log" || echo "exit $status"))"
  fi
  files="$(find "$corpus" -type f | wc -l)"
  bytes="$(du -sb "$corpus" | cut -f1)"
  rate=$(( ${inputs:-0} / (seconds > 0 ? seconds : 1) ))
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$target" "${inputs:-?}" "$seconds" "$rate" \
    "$files" "$bytes" "$result" "$started" "$load" >>"$figures"
  echo "fuzz $target: ${inputs:-?} inputs in ${seconds} s ($rate/s), $files corpus files, $result"
done
