#!/usr/bin/env bash
# The long campaign: every target for a total of 10,000,000 inputs (FUZZ_RUNS to change it)
# within the bounds of bounds.sh, one target after the other. A target's 10 million take one to
# three hours of a core, longer than a session of the machines this project runs on, and a
# machine's files do not outlive it; so the campaign is resumable: what it has done so far is
# in the repository and each run goes on from there.
#
# - fuzz/campaign/figures.tsv (in git): one line per run of a target, as it ends (inputs,
#   seconds, inputs per second, corpus size, result). A target's total is the sum of its lines;
#   a run asks libFuzzer for what is left of FUZZ_RUNS, and a target that has its total is
#   skipped.
# - fuzz/campaign/<target>.tar.gz (in git): the corpus the target has grown, minimised (cargo
#   fuzz cmin) and packed after each run, and unpacked into fuzz/campaign-corpus/<target> when
#   that is missing, so a run on a new machine starts with the coverage the last one reached,
#   not from the seeds.
# - FUZZ_MAX_SECONDS: ends each target's run after that long (libFuzzer's -max_total_time); the
#   inputs done are recorded and the rest is left for the next run.
#
# Never pause a run (SIGSTOP, a suspended laptop): libFuzzer's -timeout counts wall time, and the
# input under way when it resumes is reported as a timeout of the pause's length. Stop it with
# SIGINT (its inputs are counted) and run the campaign again later.
#
# A target that fails is recorded and the campaign goes on: the input is in
# fuzz/artifacts/<target>/, to become a regression test once fixed. Each run's full log is
# beside the figures (campaign-<target>.log, not in git).
#
#   nice -n 19 fuzz/campaign.sh                                  # every target, to its total
#   FUZZ_MAX_SECONDS=3600 fuzz/campaign.sh depth_png depth_tiff  # an hour each, then stop
#   FUZZ_RUNS=100000 FIGURES=/tmp/f.tsv fuzz/campaign.sh bop_csv # a trial, counted apart
set -uo pipefail
cd "$(dirname "$0")"
source ./toolchain.sh
source ./bounds.sh

total="${FUZZ_RUNS:-10000000}"
max_seconds="${FUZZ_MAX_SECONDS:-0}"
figures="${FIGURES:-$PWD/campaign/figures.tsv}"
logs="$(dirname "$figures")"
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${fuzz_targets[@]}")

"${fuzz_cargo[@]}" fuzz build --debug-assertions || exit 1

mkdir -p "$logs" campaign
if [ ! -s "$figures" ]; then
  printf 'target\tinputs\tseconds\tinputs_per_s\tcorpus_files\tcorpus_bytes\tresult\tstarted_utc\tload_avg_1m\n' >"$figures"
fi
for target in "${targets[@]}"; do
  fuzz_bounds "$target" || continue
  done_so_far="$(awk -F'\t' -v t="$target" '$1 == t && $2 ~ /^[0-9]+$/ { n += $2 } END { print n + 0 }' "$figures")"
  left=$(( total - done_so_far ))
  if [ "$left" -le 0 ]; then
    echo "fuzz $target: $done_so_far inputs already, nothing left of $total"
    continue
  fi
  corpus="campaign-corpus/$target"
  packed="campaign/$target.tar.gz"
  if [ ! -d "$corpus" ] && [ -f "$packed" ]; then
    mkdir -p "$corpus" && tar -xzf "$packed" -C "$corpus"
  fi
  mkdir -p "$corpus"
  log="$logs/campaign-$target.log"
  started="$(date -u +%FT%TZ)"
  load="$(cut -d' ' -f1 /proc/loadavg)"
  begin="$(date +%s)"
  limit=()
  [ "$max_seconds" -gt 0 ] && limit=(-max_total_time="$max_seconds")
  "${fuzz_cargo[@]}" fuzz run --debug-assertions "$target" "$corpus" "corpus/$target" $(ls -d "regressions/$target" 2>/dev/null) -- \
    -runs="$left" "${limit[@]}" "${bounds[@]}" -print_final_stats=1 >"$log" 2>&1
  status=$?
  seconds=$(( $(date +%s) - begin ))
  inputs="$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)"
  if [ -z "$inputs" ]; then
    # Stopped before its final statistics (a signal): the last progress line's count.
    inputs="$(grep -o '^#[0-9]*' "$log" | tail -n 1 | tr -d '#')"
  fi
  if [ "$status" -eq 0 ]; then
    result="no crash"
  elif grep -q 'libFuzzer: run interrupted' "$log"; then
    result="no crash (stopped)"
  else
    result="FAILED ($(grep -m1 -o 'ERROR: libFuzzer: [a-z-]*\|panicked at [^ ]*' "$log" || echo "exit $status"))"
  fi
  # Minimised (the fewest inputs that keep the coverage reached) before it is counted and packed.
  "${fuzz_cargo[@]}" fuzz cmin --debug-assertions "$target" "$corpus" >>"$log" 2>&1
  files="$(find "$corpus" -type f | wc -l)"
  bytes="$(find "$corpus" -type f -printf '%s\n' | awk '{ n += $1 } END { print n + 0 }')"
  rate=$(( ${inputs:-0} / (seconds > 0 ? seconds : 1) ))
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$target" "${inputs:-?}" "$seconds" "$rate" \
    "$files" "$bytes" "$result" "$started" "$load" >>"$figures"
  # Packed the same way every time (names sorted, no dates or owners), so that git stores only
  # what changed.
  tar --sort=name --mtime=@0 --owner=0 --group=0 --numeric-owner -C "$corpus" -cf - . \
    | gzip -n -9 >"$packed.tmp" && mv "$packed.tmp" "$packed"
  echo "fuzz $target: ${inputs:-?} inputs in ${seconds} s ($rate/s), $(( done_so_far + ${inputs:-0} )) of $total in all, $files corpus files, $result"
done
