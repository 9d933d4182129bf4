"""Check the documentation: the README's length, every relative link and anchor, and no session numbers or
commit hashes outside the changelog and result data.

Usage: ``.venv/bin/python scripts/check_docs.py`` from the repository root; prints one line per problem and
exits 1 when there is any (``tests/test_docs.py`` runs the same checks).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README_MAX_LINES = 250
# the git grep of the issue: a session number, or a run of 7 hex digits ending a word (a commit hash)
HISTORY_PATTERN = r"session [0-9]+|[0-9a-f]{7}\b"
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~)")


def doc_files(root: Path = ROOT) -> list[Path]:
    """The pages whose links are checked: README.md, docs/*.md, ARCHITECTURE.md, CHANGELOG.md, benchmarks/README.md."""
    names = [
        "README.md",
        "ARCHITECTURE.md",
        "CHANGELOG.md",
        "benchmarks/README.md",
        "results/README.md",
        "results/reference/README.md",
    ]
    files = [root / n for n in names if (root / n).is_file()]
    return files + sorted((root / "docs").glob("*.md"))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, markup and punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`|\*\*|__", "", heading.strip().lower())
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)  # a link keeps its text
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file, numbered as GitHub numbers repeated ones."""
    seen: dict[str, int] = {}
    out: set[str] = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line):
            fenced = not fenced
            continue
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m and not fenced:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            out.add(base if n == 0 else f"{base}-{n}")
            seen[base] = n + 1
    return out


def links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of every Markdown link outside code blocks and code spans."""
    out, fenced = [], False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if fenced:
            continue
        line = re.sub(r"`[^`]*`", "", line)
        for m in LINK.finditer(line):
            out.append((number, m.group(1) or m.group(2)))
    return out


def check_readme_length(root: Path = ROOT) -> list[str]:
    n = len((root / "README.md").read_text(encoding="utf-8").splitlines())
    return [] if n <= README_MAX_LINES else [f"README.md: {n} lines, more than {README_MAX_LINES}"]


def check_links(root: Path = ROOT) -> list[str]:
    """Every relative link resolves to a file or folder, and every ``#anchor`` to a heading of its page."""
    problems = []
    for page in doc_files(root):
        for number, target in links(page):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            path_part, _, anchor = target.partition("#")
            dest = page if not path_part else (page.parent / path_part).resolve()
            where = f"{page.relative_to(root)}:{number}: {target}"
            if not dest.exists():
                problems.append(f"{where}: no such file")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                problems.append(f"{where}: no heading with that anchor in {dest.relative_to(root)}")
    return problems


def allowed(path: str) -> bool:
    """Where session numbers and commit hashes may stay: the changelog and result data (a test's too)."""
    if path == "CHANGELOG.md" or path == "uv.lock" or path.startswith(("benchmarks/results/", "tests/data/")):
        return True
    return (
        path.startswith(
            ("results/reference/", "results/verdict-study/", "results/verdict-quick/", "results/ranges-study/")
        )
        and Path(path).name != "README.md"
    )


def check_history(root: Path = ROOT) -> list[str]:
    """``git grep -nE HISTORY_PATTERN`` outside the allowed places (tracked and staged files)."""
    run = subprocess.run(
        ["git", "grep", "--untracked", "-nIE", HISTORY_PATTERN], cwd=root, capture_output=True, text=True
    )
    if run.returncode not in (0, 1):
        return [f"git grep failed: {run.stderr.strip()}"]
    hits = [line for line in run.stdout.splitlines() if not allowed(line.split(":", 1)[0])]
    return [f"{hit[:160]}" for hit in hits]


def main() -> int:
    problems = check_readme_length() + check_links() + check_history()
    for p in problems:
        print(p)
    print(f"check_docs: {len(problems)} problem(s)", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
