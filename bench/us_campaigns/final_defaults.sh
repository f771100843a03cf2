#!/usr/bin/env bash
# The integrated-DIC acceptance campaign on femu's own simulated B-mode sequences, on the
# realizations that played no part in choosing the defaults (scatterer seeds 31-40), with the
# current code and its defaults:
#
#   bash bench/us_campaigns/final_defaults.sh [OUT_DIR]
#
# Builds and runs femu-study's `idic_campaign` example twice (seeds 31-35 at 9 then 11 MHz,
# alternating; seeds 36-40 at 11 then 9 MHz; 4 000 elements, 4 load steps, the images rendered
# from a mesh twice finer), one realization at a time, and keeps the two campaign.csv files
# joined as OUT_DIR/campaign.csv (default bench/us_campaigns/results/idic_own_final), each run's
# campaign.json, what the runs printed (campaign.log), and provenance.json (scripts/guide/provenance.sh). Then
# `scripts/guide/tables.py render idic.md` writes the page. About a minute per realization on
# two cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-bench/us_campaigns/results/idic_own_final}
# IDIC_CAMPAIGN=BIN runs that build of the example instead (e.g. one built together with other
# packages, whose features cargo unifies differently: building it alone would compile again).
if [ -n "${IDIC_CAMPAIGN:-}" ]; then
    bin=$IDIC_CAMPAIGN
else
    cargo build --release -q -p femu-study --example idic_campaign
    bin=${CARGO_TARGET_DIR:-target}/release/examples/idic_campaign
fi
. scripts/guide/provenance.sh
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
write_provenance "$scratch/provenance.json" \
    "bash bench/us_campaigns/final_defaults.sh  # idic_campaign --realizations 5 --first-seed 31 --frequencies 9,11, then --first-seed 36 --frequencies 11,9"
mkdir -p "$scratch/keep"
"$bin" --realizations 5 --first-seed 31 --frequencies 9,11 --out "$scratch/a" 2>&1 | tee "$scratch/keep/campaign.log"
"$bin" --realizations 5 --first-seed 36 --frequencies 11,9 --out "$scratch/b" 2>&1 | tee -a "$scratch/keep/campaign.log"
{ cat "$scratch/a/campaign.csv"; tail -n +2 "$scratch/b/campaign.csv"; } >"$scratch/keep/campaign.csv"
cp "$scratch/a/campaign.json" "$scratch/keep/campaign_31_35.json"
cp "$scratch/b/campaign.json" "$scratch/keep/campaign_36_40.json"
cp "$scratch/provenance.json" "$scratch/keep/"
rm -rf "$out"
mkdir -p "$(dirname "$out")"
cp -r "$scratch/keep" "$out"
chmod 755 "$out"
echo "final_defaults: wrote $out"
