#!/usr/bin/env bash
# The reference results of parts A, B and C (issue #16): the search for one, two and three sensors under the
# robust objective (the band of noise levels and bracket tolerances), each validated against the hand-placed
# layout under every condition with a held-out seed, its report, and the table of all three.
#
#   bash scripts/reference.sh            # about 50 min on 2 cores; writes results/reference/
#
# Then, per part, the found layouts and the hand one side by side under the band again (another noise seed)
# with what the brackets' tolerance does to each (the spread per axis, the bias of an un-zeroed cell, the
# bracket to make precise): results/reference/<part>/robustness/.
#
# What is kept in git: each part's report (report.html is self-contained), its small tables and layouts;
# not the search caches, the per-scan tables or the figures' source folders (see .gitignore).
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/optipose ] || bash scripts/setup.sh
out=results/reference
mkdir -p "$out"
for part in part_a part_b part_c; do
    rm -rf "$out/$part"
    .venv/bin/optipose search "$part" --budget default --objective robust --seed 0 --jobs 2 --out "$out/$part"
    .venv/bin/optipose robustness "$part" --objective robust --seed 1 --jobs 2 --out "$out/$part/robustness" \
        --layout "$out/$part/layouts/found_k1.toml" --layout "$out/$part/layouts/found_k2.toml" --layout "$out/$part/layouts/found_k3.toml"
done
.venv/bin/python scripts/search_table.py "$out/part_a" "$out/part_b" "$out/part_c" > "$out/table.md"
echo "reference: $out (table: $out/table.md)"
