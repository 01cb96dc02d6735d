# Sourced by smoke.sh and campaign.sh: how to run cargo fuzz on this machine. The fuzz build
# needs unstable compiler flags (-Zsanitizer=address): with the nightly toolchain when it is
# installed, else with the machine's stable one, which ships the same sanitizer runtime and
# takes unstable flags under RUSTC_BOOTSTRAP=1 (a machine of this project may have no other
# toolchain than stable, and none can be fetched). cargo-fuzz comes from crates.io (.ci/run
# installs it).

if cargo +nightly --version >/dev/null 2>&1; then
  fuzz_cargo=(cargo +nightly)
else
  echo "fuzz: no nightly toolchain; building with $(rustc --version) and RUSTC_BOOTSTRAP=1" >&2
  export RUSTC_BOOTSTRAP=1
  fuzz_cargo=(cargo)
fi
if ! "${fuzz_cargo[@]}" fuzz --version >/dev/null 2>&1; then
  echo "fuzz: cargo-fuzz is missing; install it with \`cargo install --locked cargo-fuzz\`" >&2
  exit 1
fi
