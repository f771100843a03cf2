#!/usr/bin/env bash
# `femu dic-check` on the six shared GE Logiq E9 frames (../shared/data/ultrasound/
# logiq-e9-gastrocnemius: the lateral gastrocnemius during a jump), for the real-frame figures
# of docs/guide/src/measured/dic.md:
#
#   bash bench/dic_real/run.sh FEMU_BIN [DATA_DIR] [OUT_DIR]
#
# Each configuration below runs `femu dic-check` on frames 048 to its last frame with its ROI and
# options (the others at their defaults); its checks.csv and pairs.csv (and for the whole ROI
# its points.csv, gzipped) land in OUT_DIR/NAME/
# (default bench/dic_real/results), beside configs.csv (name, ROI, frames, options, wall time,
# the correlation that did not converge when one stopped dic-check) and provenance.json
# (scripts/guide/provenance.sh). Then `scripts/guide/tables.py render dic.md` writes the page.
# About 3 minutes on two cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
femu=${1:?usage: bash bench/dic_real/run.sh FEMU_BIN [DATA_DIR] [OUT_DIR]}
data=${2:-../shared/data/ultrasound/logiq-e9-gastrocnemius}
out=${3:-bench/dic_real/results}
[ -x "$femu" ] || { echo "dic_real: $femu is not an executable" >&2; exit 2; }
frames=()
for n in 048 050 052 054 056 058; do
    f="$data/gastroc_jumping_$n.png"
    [ -f "$f" ] || { echo "dic_real: no frame $f" >&2; exit 2; }
    frames+=("$f")
done
# name | ROI | last frame | options beyond the defaults. Above the deep aponeurosis the fast
# phase (052 -> 056 directly) does not correlate: those configurations stop at frame 054.
configs=(
    "whole|144,80,512x416|058|"
    "whole-regularization-256|144,80,512x416|058|--regularization 256"
    "above-aponeurosis|144,80,512x288|054|"
    "above-aponeurosis-regularization-256|144,80,512x288|054|--regularization 256"
    "above-aponeurosis-element-24|144,80,512x288|054|--element 24"
    "above-aponeurosis-element-32|144,80,512x288|054|--element 32"
    "soleus|144,392,512x112|054|"
)
. scripts/guide/provenance.sh
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
FEMU_BIN=$femu write_provenance "$scratch/provenance.json" \
    "bash bench/dic_real/run.sh $femu  # femu dic-check FRAMES --roi ROI OPTIONS per configuration"
echo "name,roi,frames,options,wall_s,error" >"$scratch/configs.csv"
for c in "${configs[@]}"; do
    IFS='|' read -r name roi last opts <<<"$c"
    use=()
    for f in "${frames[@]}"; do
        use+=("$f")
        [ "$(basename "$f" .png)" = "gastroc_jumping_$last" ] && break
    done
    start=$(date +%s%N)
    status=0
    # shellcheck disable=SC2086
    "$femu" dic-check "${use[@]}" --roi "$roi" $opts --no-figures -q --out "$scratch/run/$name" \
        2>"$scratch/$name.err" || status=$?
    ms=$((($(date +%s%N) - start) / 1000000))
    # A correlation that does not converge stops dic-check: the configuration is kept with the
    # first line of its message, and the table says so.
    error=""
    if [ "$status" -ne 0 ]; then
        error=$(grep -m1 -o 'gastroc_jumping_[0-9]* -> gastroc_jumping_[0-9]*: [^:]*' "$scratch/$name.err" || head -1 "$scratch/$name.err")
        cat "$scratch/$name.err" >&2
    else
        mkdir -p "$scratch/$name"
        cp "$scratch/run/$name/checks.csv" "$scratch/run/$name/pairs.csv" "$scratch/$name/"
        # Every point of every check for the whole ROI (the correlation of the forward-backward
        # discrepancy with the composition error on the guide's DIC page), compressed.
        [ "$name" = whole ] && gzip -9n <"$scratch/run/$name/points.csv" >"$scratch/$name/points.csv.gz"
    fi
    rm -f "$scratch/$name.err"
    echo "$name,\"$roi\",048-$last,$opts,$((ms / 1000)).$(printf %03d $((ms % 1000))),\"${error//\"/}\"" >>"$scratch/configs.csv"
    echo "dic_real: $name done ($((ms / 1000)) s, exit $status)"
done
rm -rf "$scratch/run" "$out"
mkdir -p "$(dirname "$out")"
cp -r "$scratch" "$out"
chmod 755 "$out"
echo "dic_real: wrote $out"
