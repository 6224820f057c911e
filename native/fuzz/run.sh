#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 60) and prints the executions per target.
#
#   native/fuzz/run.sh [seconds] [extra libFuzzer flags, e.g. -max_len=65536]
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
cd "$(dirname "$0")"
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked
fi
targets=(nff toml_scene obj)
status=0
summary=()
for t in "${targets[@]}"; do
    work="target/fuzz-corpus/$t"
    log="target/fuzz-$t.log"
    mkdir -p "$work"
    echo "== $t: ${secs}s" >&2
    rc=0
    cargo +nightly fuzz run "$t" "$work" "corpus/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
        ${extra[@]+"${extra[@]}"} >"$log" 2>&1 || rc=$?
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
    if [ -z "$execs" ]; then
        execs=$(grep -oE '^#[0-9]+' "$log" | tail -1 | tr -d '#')
    fi
    if [ "$rc" -ne 0 ]; then
        status=1
        summary+=("$t: ${execs:-?} execs, FAILED (exit $rc), see native/fuzz/$log and native/fuzz/artifacts/$t/")
        grep -E 'panicked|ERROR: libFuzzer|SUMMARY|Test unit written' "$log" >&2 || true
    else
        summary+=("$t: ${execs:-?} execs, no crash")
    fi
done
printf '%s\n' "${summary[@]}"
exit "$status"
