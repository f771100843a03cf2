#!/usr/bin/env bash
# muDIC 0.2.1 (global Q4 without regularization) against femu-dic on the six shared GE Logiq E9
# frames, for the real-frame paragraph of docs/guide/src/measured/dic.md:
#
#   bash bench/dic_real/mudic.sh PYTHON [OUT_DIR]
#
# PYTHON: a Python with muDIC (`python3 -m venv V && V/bin/pip install muDIC==0.2.1 pillow`).
# Runs crates/femu-dic/examples/compare_mudic.rs (every consecutive pair correlated by femu-dic
# with its defaults and by muDIC with 32 px elements on the same ROI, started from femu-dic's
# FFT shift; the fields compared over femu-dic's trusted nodes) and keeps its compare.json beside
# provenance.json in OUT_DIR (default bench/dic_real/results_mudic). About 2 minutes on two cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
python=${1:?usage: bash bench/dic_real/mudic.sh PYTHON [OUT_DIR]}
out=${2:-bench/dic_real/results_mudic}
"$python" -c "import muDIC" 2>/dev/null || { echo "mudic.sh: $python has no muDIC" >&2; exit 2; }
version=$("$python" -m pip show muDIC 2>/dev/null | awk '/^Version/ {print $2}')
. scripts/guide/provenance.sh
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cargo build --release --locked -q -p femu-dic --example compare_mudic
write_provenance "$scratch/provenance.json" \
    "bash bench/dic_real/mudic.sh PYTHON  # cargo run --release -p femu-dic --example compare_mudic -- --python PYTHON (muDIC $version)"
cargo run --release --locked -q -p femu-dic --example compare_mudic -- --python "$python" --out "$scratch/run"
mkdir -p "$scratch/keep"
cp "$scratch/run/compare.json" "$scratch/provenance.json" "$scratch/keep/"
rm -rf "$out"
mkdir -p "$(dirname "$out")"
cp -r "$scratch/keep" "$out"
chmod 755 "$out"
echo "mudic.sh: wrote $out"
