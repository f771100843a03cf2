#!/usr/bin/env bash
# An independent DIC's composition check on the shared GE Logiq E9 frames, for the guide's DIC
# page: scikit-image's iterative Lucas-Kanade (crates/femu-dic/bench/lk_composition.py) on
# 048->050, 050->052 and 048->052, the two steps composed and compared with the direct one over
# the ROI 144,80,512x416 (points every 8 px), radius 7 and 15 px, unsmoothed and smoothed by a
# Gaussian of 4 px:
#
#   bash bench/dic_lk/run.sh [FRAMES_DIR] [PYTHON]
#
# FRAMES_DIR defaults to /work/shared/data/ultrasound/logiq-e9-gastrocnemius, PYTHON to python3
# (it needs numpy, scipy, Pillow and scikit-image). Writes bench/dic_lk/results/
# lk_composition.csv and provenance.json (scripts/guide/provenance.sh); then
# `python3 scripts/guide/tables.py render dic.md > docs/guide/src/measured/dic.md`. About a
# minute of CPU (3 min under load on two cores).
set -euo pipefail
cd "$(dirname "$0")/../.."
frames=${1:-/work/shared/data/ultrasound/logiq-e9-gastrocnemius}
py=${2:-python3}
out=bench/dic_lk/results
. scripts/guide/provenance.sh
mkdir -p "$out"
BUILD="no build (Python: $("$py" -c 'import skimage; print("scikit-image", skimage.__version__)'))" \
    write_provenance "$out/provenance.json" "bash bench/dic_lk/run.sh  # $py crates/femu-dic/bench/lk_composition.py FRAMES_DIR"
"$py" crates/femu-dic/bench/lk_composition.py "$frames" | "$py" -c '
import re, sys
print("radius_px,smoothing_px,rms_x_px,rms_y_px,mean_x_px,mean_y_px")
pat = re.compile(r"radius (\d+) px, smoothing (\d+) px: composition RMS \(([-\d.]+), ([-\d.]+)\) px, "
                 r"mean motion 048->052 \(([-\d.]+), ([-\d.]+)\) px")
n = 0
for line in sys.stdin:
    m = pat.match(line.strip())
    if not m:
        sys.exit(f"lk_composition.py: unexpected line {line!r}")
    print(",".join(m.groups()))
    n += 1
if n == 0:
    sys.exit("lk_composition.py printed nothing")
' >"$out/lk_composition.csv"
cat "$out/lk_composition.csv"
