"""What the command-line tests share: running ``optipose`` as a user would, and the one-line error check."""

from __future__ import annotations

import subprocess
import sys

PAPER_S2 = "0,1,0,0.03, 1,0,0,0, 0,0,-1,0.0175, 0,0,0,1"  # part B's S2, straight down at its top
# a --search-config of ~160 surrogate evaluations of one sensor and no ICP stage but the validation
SMALL_SEARCH = """[search]
global_evals = 150
local_evals = 10
random_starts = 2
select_candidates = 0
screen_samples = 0
polish_evals = 0
confirm_candidates = 0
"""


def run(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "optipose", *args], capture_output=True, text=True, cwd=cwd, timeout=120
    )


def assert_one_line_error(result, fragment):
    """Exit code 2 and the error in one line ``optipose: error: ...``, the last on stderr. Lines before it
    are the command's progress (off a terminal, a line as each stage starts and ends), never part of it."""
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if not line.startswith("WARNING")]
    errors = [line for line in lines if line.startswith("optipose: error:")]
    assert len(errors) == 1 and lines[-1] == errors[0], result.stderr
    assert fragment in errors[0], errors[0]
    assert "Traceback" not in result.stderr and "╭" not in result.stderr
