#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 60) and prints the executions per target.
#
#   native/fuzz/run.sh [seconds] [extra libFuzzer flags, e.g. -max_len=65536 or -runs=10000000]
#
# Environment: FUZZ_SANITIZER (cargo fuzz's -s: address, the default, or none, several times
# faster; the kernel has no unsafe code of its own), FUZZ_PARALLEL=1 to run the three targets
# at once instead of one after another.
#
# Needs the nightly toolchain (`rustup toolchain install nightly`); installs cargo-fuzz if
# missing. Seeds come from corpus/<target>/ (committed, read-only here); what libFuzzer adds goes
# to target/fuzz-corpus/<target>/ so the committed corpora stay small. Crashes land in
# artifacts/<target>/; reproduce one with `cargo +nightly fuzz run <target> <file>`, then add
# the minimised input (`cargo +nightly fuzz tmin <target> <file>`) to
# native/kernel/tests/robustness.rs.
set -euo pipefail
secs="${1:-60}"
shift || true
extra=("$@")
sanitizer="${FUZZ_SANITIZER:-address}"
cd "$(dirname "$0")"
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked
fi
targets=(nff toml_scene obj)
# build all first, so that parallel runs do not race on the build
cargo +nightly fuzz build -s "$sanitizer" >&2

one() {
    local t=$1 work="target/fuzz-corpus/$1" log="target/fuzz-$1.log" rc=0
    mkdir -p "$work"
    echo "== $t: ${secs}s" >&2
    cargo +nightly fuzz run -s "$sanitizer" "$t" "$work" "corpus/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
        ${extra[@]+"${extra[@]}"} >"$log" 2>&1 || rc=$?
    echo "$rc" >"target/fuzz-$t.rc"
}

if [ "${FUZZ_PARALLEL:-0}" = 1 ]; then
    for t in "${targets[@]}"; do one "$t" & done
    wait
else
    for t in "${targets[@]}"; do one "$t"; done
fi

status=0
for t in "${targets[@]}"; do
    log="target/fuzz-$t.log"
    rc=$(cat "target/fuzz-$t.rc")
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
    if [ -z "$execs" ]; then
        execs=$(grep -oE '^#[0-9]+' "$log" | tail -1 | tr -d '#')
    fi
    if [ "$rc" -ne 0 ]; then
        status=1
        echo "$t: ${execs:-?} execs, FAILED (exit $rc), see native/fuzz/$log and native/fuzz/artifacts/$t/"
        grep -E 'panicked|ERROR: libFuzzer|SUMMARY|Test unit written' "$log" >&2 || true
    else
        echo "$t: ${execs:-?} execs, no crash (sanitizer: $sanitizer)"
    fi
done
exit "$status"
