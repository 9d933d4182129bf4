#!/usr/bin/env bash
# The reference results of parts A, B and C (issues #16, #33): the search for one, two and three sensors in the
# paper's cell (`optipose search PART --budget default --seed 0 --jobs 2`: the objective `paper`, cell `ur10e`),
# its verdict with confidence and report, then a held-out check of each verdict (the found layouts and the hand
# one again on other cell instances, seed 1000, raced on draws alone: with the choices of subsets the search
# made, and with choices made again there), and the table of all three.
#
#   bash scripts/reference.sh            # about 15 min on 2 cores; writes results/reference/
#
# What is kept in git: each part's report (report.html is self-contained), its small tables and layouts;
# not the search caches, the per-scan tables or the figures' source folders (see .gitignore).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/optipose ] || bash scripts/setup.sh
out=results/reference
mkdir -p "$out"
rm -rf "$out"/part_a "$out"/part_b "$out"/part_c
.venv/bin/python benchmarks/bench_verdict_study.py run --parts part_a,part_b,part_c --report --out "$out"
.venv/bin/python benchmarks/bench_verdict_study.py holdout --parts part_a,part_b,part_c --verdict-time 0 --out "$out"
.venv/bin/python benchmarks/bench_verdict_study.py holdout --parts part_a,part_b,part_c --verdict-time 0 --out "$out" \
    --choices remade --file holdout-remade.csv
.venv/bin/python benchmarks/bench_verdict_study.py table --out "$out" > "$out/table.md"
echo "reference: $out (table: $out/table.md)"
