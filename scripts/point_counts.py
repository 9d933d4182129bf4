"""Print nominal-scan point counts per sensor for the shipped parts' hand layouts.

Usage: ``.venv/bin/python scripts/point_counts.py [PART ...] [--markdown]`` (docs/parts.md's point counts are
the ``--markdown`` output).
"""

import sys

from optipose.cli.parts import counts_command

if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    for name in args or [None]:
        counts_command(name, markdown="--markdown" in sys.argv)
