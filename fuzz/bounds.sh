# Sourced by smoke.sh and campaign.sh: the targets, and the bounds every fuzz run holds each
# input to, as libFuzzer options (the README's "Fuzzing" section gives the measurements they
# come from). A run that meets a bound stops and fails, as on a crash, with the input saved.
#
# - Size: inputs of at most 64 KiB (-max_len). fuzz/largest/<target> is a valid input of about
#   that size (corpus/make.py writes it).
# - Allocation: no single allocation above 64 MiB (-malloc_limit_mb), 1 KiB per byte of the
#   largest input: each largest valid input allocates less than 1 MiB at once, and the bound
#   leaves room for the largest depth image BOP publishes (2,560 x 2,048 16-bit pixels, 10 MiB)
#   compressed into 64 KiB. The process stays under 2 GiB resident (-rss_limit_mb), the
#   AddressSanitizer's shadow memory and quarantine included.
# - Time (-timeout, whole seconds): 100 times what the target's largest valid input takes,
#   rounded up, as measured on the loaded development machine (quiet, the same inputs run
#   faster, so the bound is looser there).

fuzz_targets=(bop_csv bop22_json ply depth_png depth_tiff dataset_json archive multipart forms)

# fuzz_bounds TARGET: sets the array `bounds` to TARGET's libFuzzer options.
fuzz_bounds() {
  local timeout
  case "$1" in
    bop_csv) timeout=3 ;;      # 21.6 ms for 54 KiB
    bop22_json) timeout=9 ;;   # 82 ms for 64 KiB
    ply) timeout=7 ;;          # 69 ms for 38 KiB (the largest fixture mesh)
    depth_png) timeout=5 ;;    # 40 ms for 63 KiB
    depth_tiff) timeout=2 ;;   # 12 ms for 63 KiB
    dataset_json) timeout=3 ;; # 22 ms for 64 KiB
    archive) timeout=6 ;;      # 51 ms for 62 KiB
    multipart) timeout=1 ;;    # 1.7 ms for 53 KiB
    forms) timeout=2 ;;        # 12 ms for 11 KiB (the longest form the fields allow)
    *) echo "fuzz: no bounds for target $1" >&2; return 1 ;;
  esac
  bounds=(-max_len=65536 -malloc_limit_mb=64 -rss_limit_mb=2048 -timeout="$timeout")
}
