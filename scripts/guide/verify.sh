#!/usr/bin/env bash
# Runs the verification tests with their measured values recorded, and rewrites
# docs/guide/src/measured/verification.md from what they record.
#
#   bash scripts/guide/verify.sh [OUT_DIR]                        # every target: the full rerun
#   bash scripts/guide/verify.sh --only CRATE:TEST[,CRATE:TEST...] [OUT_DIR]
#
# Each test target below runs as `cargo test --release -p CRATE --test TEST` (TEST `lib`: the
# crate's unit tests, `cargo test --release -p CRATE --lib`) with FEMU_MEASURE_DIR set: the
# tests append one JSON line per measured quantity (test, quantity, value, the bound they
# assert, unit) to CRATE-TEST.jsonl (scripts/guide/measure.rs), which lands in OUT_DIR (default bench/verification/results). Beside them: provenance.json (machine
# and build; scripts/guide/provenance.sh) and targets.json (each target's date, commit, machine
# and load average when it started, its wall time, its tests' own time and exit status).
#
# The full rerun (no --only) measures every target and replaces OUT_DIR. With --only, only the
# targets named are built and run: their files replace theirs in OUT_DIR, their entries in
# targets.json are replaced, and the other targets' files and entries are kept as they were, so
# each table of the page keeps the date and commit it was measured at.
#
# The tests record into a scratch directory first: a target that fails stops the script and
# OUT_DIR and the page are left as they were. Then `scripts/guide/tables.py verification` writes
# the page (and, from bench/verification/results, the DIC page, which quotes some values). On
# two cores (load average 2.5) the full rerun took 2 minutes of release build from a warm target
# directory (a quarter of an hour from a cold one) and 4 minutes of tests.
set -euo pipefail
cd "$(dirname "$0")/../.."
all=(
    femu-mech:derivatives femu-mech:verification femu-mech:contact femu-mech:sensitivity
    femu-mech:calculix femu-mech:solid3d femu-mech:solid3d_newton femu-mech:thigh3d_calculix
    femu-mech:interface femu-mech:interface_calculix
    femu-geometry:thigh
    femu-dic:virtual_lab femu-dic:dic_challenge femu-dic:covariance femu-dic:sequence
    femu-dic:bmode_pair femu-dic:ultrasound femu-dic:second_opinion femu-dic:dicom
    femu-dic:dicom_jpeg
    femu-identify:identification femu-identify:joint femu-identify:calculix
    femu-identify:discretization femu-identify:weighted femu-identify:idic
    femu-identify:pose_term femu-identify:lib
    femu-mesh:locate femu-cli:sensitivity_cmd femu-cli:run_cmd
    femu-convergence:convergence
)
only=""
if [ "${1:-}" = "--only" ]; then
    [ $# -ge 2 ] || { echo "verify: --only needs CRATE:TEST[,CRATE:TEST...]" >&2; exit 2; }
    only=$2
    shift 2
fi
out=${1:-bench/verification/results}
if [ -n "$only" ]; then
    IFS=, read -r -a targets <<<"$only"
    for t in "${targets[@]}"; do
        found=0
        for a in "${all[@]}"; do [ "$a" = "$t" ] && found=1; done
        if [ "$found" -eq 0 ]; then
            echo "verify: --only: $t is not a verification target; the targets are: ${all[*]}" >&2
            exit 2
        fi
    done
else
    targets=("${all[@]}")
fi
. scripts/guide/provenance.sh

# The cargo arguments of a target: its test binary, or the library's unit tests.
selector() { if [ "${1#*:}" = lib ]; then echo "--lib"; else echo "--test ${1#*:}"; fi; }

# Build the test binaries first, so that the times below are the tests' own.
build=()
for t in "${targets[@]}"; do build+=(-p "${t%%:*}" $(selector "$t")); done
cargo test --release --no-run "${build[@]}"

command -v ccx >/dev/null 2>&1 || echo "warning: no ccx: the CalculiX comparisons skip and record nothing"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
mkdir -p "$scratch/results" "$scratch/logs"
BUILD="release build (cargo test --release)" write_provenance "$scratch/provenance.json" \
    "bash scripts/guide/verify.sh  # cargo test --release -p CRATE --test NAME, FEMU_MEASURE_DIR set"
: >"$scratch/targets.jsonl"
for t in "${targets[@]}"; do
    crate=${t%%:*} name=${t#*:}
    write_provenance "$scratch/started.json" "-"
    start=$(date +%s%N)
    status=0
    # shellcheck disable=SC2046
    FEMU_MEASURE_DIR="$scratch/results" cargo test --release -q -p "$crate" $(selector "$t") \
        >"$scratch/logs/$crate-$name.log" 2>&1 || status=$?
    # Unit tests record under the library's crate name (measure.rs): the target's name instead.
    lib_file="$scratch/results/$crate-${crate//-/_}.jsonl"
    if [ "$name" = lib ] && [ -f "$lib_file" ]; then mv "$lib_file" "$scratch/results/$crate-lib.jsonl"; fi
    ds=$((($(date +%s%N) - start) / 100000000))
    seconds=$((ds / 10)).$((ds % 10))
    # The tests' own time, as libtest reports it ("finished in 1.23s"); the wall time above also
    # holds a rebuild when the sources changed since the build step.
    test_seconds=$(sed -n 's/.*finished in \([0-9.]*\)s.*/\1/p' "$scratch/logs/$crate-$name.log" | tail -1)
    python3 - "$scratch/started.json" "$crate" "$name" "$seconds" "${test_seconds:-}" "$status" \
        >>"$scratch/targets.jsonl" <<'PY'
import json, sys
p = json.load(open(sys.argv[1]))
crate, test, seconds, test_seconds, status = sys.argv[2:]
print(json.dumps({"crate": crate, "test": test, "date": p["date"], "machine": p["machine"],
                  "commit": p["commit"], "load": p["load"], "seconds": float(seconds),
                  "test_seconds": float(test_seconds) if test_seconds else None,
                  "status": int(status)}, ensure_ascii=False))
PY
    echo "$crate $(selector "$t"): exit $status, $seconds s"
    if [ "$status" -ne 0 ]; then
        tail -40 "$scratch/logs/$crate-$name.log"
        mkdir -p /tmp/femu-verify-logs
        cp "$scratch/logs/$crate-$name.log" /tmp/femu-verify-logs/
        echo "verify: $crate $(selector "$t") failed (log: /tmp/femu-verify-logs/$crate-$name.log);" \
            "$out and the page are left as they were"
        exit 1
    fi
done

# Every target passed: its files replace its old ones in OUT_DIR.
if [ -z "$only" ]; then
    rm -rf "$out"
fi
mkdir -p "$out"
for t in "${targets[@]}"; do
    rm -f "$out/${t%%:*}-${t#*:}.jsonl"
done
cp "$scratch"/results/*.jsonl "$out"/ 2>/dev/null || true
[ -n "$only" ] && [ -f "$out/provenance.json" ] || cp "$scratch/provenance.json" "$out/provenance.json"
python3 - "$out/targets.json" "$scratch/targets.jsonl" "${all[*]}" <<'PY'
import json, os, sys
path, new_path, order = sys.argv[1], sys.argv[2], sys.argv[3].split()
entries = {}
if os.path.exists(path):
    for e in json.load(open(path)):
        entries[f"{e['crate']}:{e['test']}"] = e
for line in open(new_path):
    e = json.loads(line)
    entries[f"{e['crate']}:{e['test']}"] = e
kept = [entries[t] for t in order if t in entries]
with open(path, "w") as f:
    f.write("[\n" + ",\n".join(" " + json.dumps(e, ensure_ascii=False) for e in kept) + "\n]\n")
PY
python3 scripts/guide/tables.py verification "$out" >docs/guide/src/measured/verification.md
echo "wrote docs/guide/src/measured/verification.md from $out"
# The DIC page quotes some of the real-frame values (tables.py's `recorded`).
if [ "$out" -ef bench/verification/results ]; then
    python3 scripts/guide/tables.py render dic.md >docs/guide/src/measured/dic.md
    echo "wrote docs/guide/src/measured/dic.md"
fi
