"""The documentation's own checks (``scripts/check_docs.py``): the README's length, every relative link and
anchor, and no session numbers or commit hashes outside CHANGELOG.md and result data."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("check_docs", ROOT / "scripts" / "check_docs.py")
check_docs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_docs)


def test_readme_is_short():
    assert check_docs.check_readme_length() == []


def test_every_link_and_anchor_resolves():
    assert check_docs.check_links() == []


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="needs a git checkout")
def test_no_session_numbers_or_commit_hashes_outside_the_changelog():
    assert check_docs.check_history() == []


def test_slugs_are_github_s():
    assert check_docs.slug("The assignment: the paper's Table 1") == "the-assignment-the-papers-table-1"
    assert check_docs.slug("`bench_scanner.py` — the virtual scanner") == "bench_scannerpy--the-virtual-scanner"
    assert check_docs.slug('How finely "no worse" can be told') == "how-finely-no-worse-can-be-told"


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("# Title\n\n[ok](#title) [bad](#nothing) [gone](docs/none.md)\n")
    problems = check_docs.check_links(tmp_path)
    assert len(problems) == 2 and "#nothing" in problems[0] and "docs/none.md" in problems[1]
