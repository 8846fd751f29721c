#!/usr/bin/env bash
# Fuzzes every target (or the ones named) for SECONDS each, one after the
# other, and prints a markdown table of executions per target.
#
#   fuzz/run.sh 40          # the CI-sized run (.ci/run): 8 x 40 s
#   fuzz/run.sh 300         # the long run (docs/robustness.md)
#   fuzz/run.sh 60 nrrd     # one target
#
# It works on the stable toolchain alone: cargo-fuzz's coverage
# instrumentation (-Cpasses=sancov-module, -Cllvm-args=-sanitizer-coverage-*)
# and --cfg fuzzing are stable flags; only the sanitizers need nightly, so the
# targets are built with --sanitizer none. What catches bugs is Rust's own
# checks (bounds, unwrap, overflow and debug assertions: -a) plus the
# invariants the targets assert; a hang past FUZZ_TIMEOUT seconds on one input
# and an RSS over 2 GiB count as crashes too.
#
# Any crash makes the script exit 1 (after every target has run); its input
# is left in fuzz/artifacts/TARGET/ and its log in fuzz/artifacts/logs/.
# Reproduce with: cargo fuzz run -O -a --sanitizer none TARGET fuzz/artifacts/TARGET/crash-...
set -euo pipefail
cd "$(dirname "$0")/.."

CARGO_FUZZ_VERSION=0.13.2
usage="usage: fuzz/run.sh SECONDS_PER_TARGET [TARGET...]"
secs=${1:?$usage}
shift
case "$secs" in
  '' | *[!0-9]*) echo "$usage" >&2; exit 2 ;;
esac
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(nrrd nhdr nifti metaimage raw scene exr photo)
fi
timeout_s=${FUZZ_TIMEOUT:-30}

# cargo install puts it in $CARGO_HOME/bin; make sure `cargo fuzz` finds it
# there even when that directory is not on PATH.
tools="${CARGO_HOME:-$HOME/.cargo}"
export PATH="$tools/bin:$PATH"
if ! cargo fuzz --version 2>/dev/null | grep -qF "cargo-fuzz $CARGO_FUZZ_VERSION"; then
  echo "installing cargo-fuzz $CARGO_FUZZ_VERSION"
  cargo install cargo-fuzz --version "$CARGO_FUZZ_VERSION" --locked --root "$tools"
fi
cargo fuzz --version | grep -F "cargo-fuzz $CARGO_FUZZ_VERSION"
rustc --version

flags=(-O --debug-assertions --sanitizer none)
build_start=$(date +%s)
cargo fuzz build "${flags[@]}"
echo "fuzz targets built in $(($(date +%s) - build_start)) s"

logs=fuzz/artifacts/logs
mkdir -p "$logs"
# The targets write their inputs to files here (on tmpfs when there is one).
SNELL_FUZZ_SCRATCH=$(mktemp -d /dev/shm/snell-fuzz.XXXXXX 2>/dev/null || mktemp -d)
export SNELL_FUZZ_SCRATCH
trap 'rm -rf "$SNELL_FUZZ_SCRATCH"' EXIT
rows=()
failed=()
for t in "${targets[@]}"; do
  mkdir -p "fuzz/corpus/$t"
  log="$logs/$t.log"
  echo "== fuzz $t for $secs s"
  status=0
  cargo fuzz run "${flags[@]}" "$t" "fuzz/corpus/$t" "fuzz/seeds/$t" -- \
    -max_total_time="$secs" -timeout="$timeout_s" -rss_limit_mb=2048 \
    -print_final_stats=1 >"$log" 2>&1 || status=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  corpus=$(find "fuzz/corpus/$t" -type f | wc -l)
  if [ "$status" -eq 0 ]; then
    result="no crash"
  else
    result="CRASH (exit $status)"
    failed+=("$t")
    echo "-- $t failed; the panic and the end of $log:"
    grep -m 3 -A 2 "panicked at" "$log" || true
    tail -n 40 "$log"
  fi
  echo "$t: ${execs:-?} executions (${rate:-?}/s), corpus $corpus files, $result"
  rows+=("| $t | $secs | ${execs:-?} | ${rate:-?} | $corpus | $result |")
done

echo
echo "| target | seconds | executions | exec/s | corpus files | result |"
echo "|---|---|---|---|---|---|"
printf '%s\n' "${rows[@]}"
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzzing found crashes in: ${failed[*]} (inputs in fuzz/artifacts/)" >&2
  exit 1
fi
