#!/usr/bin/env bash
# Measures the runs behind docs/guide/src/measured/runs.md and rewrites that page from them.
#
#   bash scripts/guide/measure.sh FEMU_BINARY [OUT_DIR]
#
# Runs `femu demo`, `femu convergence` (its defaults) and, when CalculiX (`ccx`) is installed,
# `femu bench --repeat 5`, one after the other, each into OUT_DIR (default out/measured) with a
# provenance.json beside its outputs: the date, the machine (CPU model, cores, memory), the commit
# of the sources (COMMIT=... when the binary was built from another one than this clone's HEAD),
# the load average when it started and the command. The files the page is made from (each run's
# summary.json, the convergence table, provenance.json) are copied to bench/runs/results/, which
# is committed: `python3 scripts/guide/tables.py check` remakes the page from them. Then
# scripts/guide/tables.py writes the page.
# A release build is what the page is about: `cargo build --release --bin femu`.
set -euo pipefail
femu=$(readlink -f "${1:?usage: measure.sh FEMU_BINARY [OUT_DIR]}")
out=${2:-out/measured}
cd "$(dirname "$0")/../.."
. scripts/guide/provenance.sh

run() { # NAME COMMAND...
    local dir=$out/$1
    shift
    rm -rf "$dir"
    mkdir -p "$dir"
    write_provenance "$dir/provenance.json" "$@"
    "$@" >"$dir.log" 2>&1
}

export FEMU_BIN=$femu
run demo "$femu" demo --out "$out/demo" --quiet
run convergence "$femu" convergence --out "$out/convergence" --quiet
bench=""
if command -v ccx >/dev/null 2>&1; then
    run bench "$femu" bench --repeat 5 --out "$out/bench"
    bench=$out/bench
fi
results=bench/runs/results
rm -rf "$results"
for name in demo convergence ${bench:+bench}; do
    mkdir -p "$results/$name"
    cp "$out/$name/provenance.json" "$out/$name/summary.json" "$results/$name/"
done
cp "$out/convergence/convergence.csv" "$results/convergence/"
python3 scripts/guide/tables.py runs "$results" >docs/guide/src/measured/runs.md
echo "wrote docs/guide/src/measured/runs.md from $out (result files in $results)"
