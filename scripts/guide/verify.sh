#!/usr/bin/env bash
# Runs the verification tests with their measured values recorded, and rewrites
# docs/guide/src/measured/verification.md from what they record.
#
#   bash scripts/guide/verify.sh [OUT_DIR]
#
# Each test target below runs as `cargo test --release -p CRATE --test NAME` with
# FEMU_MEASURE_DIR=OUT_DIR (default bench/verification/results): the tests append one JSON line
# per measured quantity (test, quantity, value, the bound they assert, unit) to
# OUT_DIR/CRATE-NAME.jsonl (scripts/guide/measure.rs). Beside them: provenance.json (date,
# machine, commit, command; scripts/guide/provenance.sh) and targets.json (each target's wall
# time, its tests' own time and exit status). A target that fails stops the script: the page is only rewritten from
# tests that passed. Then `scripts/guide/tables.py verification` writes the page. On two busy
# cores the release build of the test binaries took 16 minutes and the tests 23 more.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-bench/verification/results}
targets=(
    femu-mech:derivatives femu-mech:verification femu-mech:contact femu-mech:sensitivity
    femu-mech:calculix femu-geometry:thigh femu-dic:virtual_lab femu-dic:dic_challenge
    femu-identify:identification femu-identify:joint femu-identify:calculix
    femu-convergence:convergence
)
. scripts/guide/provenance.sh

# Build every test binary first, so that the times below are the tests' own.
build=()
for t in "${targets[@]}"; do build+=(-p "${t%%:*}" --test "${t#*:}"); done
cargo test --release --no-run "${build[@]}"

rm -rf "$out"
mkdir -p "$out"
BUILD="release build (cargo test --release)" write_provenance "$out/provenance.json" \
    "bash scripts/guide/verify.sh  # cargo test --release -p CRATE --test NAME, FEMU_MEASURE_DIR set"
command -v ccx >/dev/null 2>&1 || echo "warning: no ccx: the CalculiX comparisons skip and record nothing"
log=$(mktemp -d)
echo "[" >"$out/targets.json"
sep=""
for t in "${targets[@]}"; do
    crate=${t%%:*} name=${t#*:}
    start=$(date +%s%N)
    status=0
    FEMU_MEASURE_DIR=$(readlink -f "$out") cargo test --release -q -p "$crate" --test "$name" \
        >"$log/$crate-$name.log" 2>&1 || status=$?
    ds=$((($(date +%s%N) - start) / 100000000))
    seconds=$((ds / 10)).$((ds % 10))
    # The tests' own time, as libtest reports it ("finished in 1.23s"); the wall time above also
    # holds a rebuild when the sources changed since the build step.
    test_seconds=$(sed -n 's/.*finished in \([0-9.]*\)s.*/\1/p' "$log/$crate-$name.log" | tail -1)
    printf '%s {"crate": "%s", "test": "%s", "seconds": %s, "test_seconds": %s, "status": %d}\n' \
        "$sep" "$crate" "$name" "$seconds" "${test_seconds:-null}" "$status" >>"$out/targets.json"
    sep=","
    echo "$crate --test $name: exit $status, $seconds s"
    if [ "$status" -ne 0 ]; then
        tail -40 "$log/$crate-$name.log"
        echo "verify: $crate --test $name failed (log: $log/$crate-$name.log); the page is not rewritten"
        exit 1
    fi
done
echo "]" >>"$out/targets.json"
rm -rf "$log"
python3 scripts/guide/tables.py verification "$out" >docs/guide/src/measured/verification.md
echo "wrote docs/guide/src/measured/verification.md from $out"
