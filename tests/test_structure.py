"""The rules the tree keeps (ARCHITECTURE.md, "Rules the tree keeps"), checked on the source: no import cycle
between optipose's modules (imports inside functions count: a lazy import hides a cycle, it does not remove
it), no module over 450 lines, no private name imported from another module, and the verdict's names imported
from the verdict package only."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "optipose"
MAX_LINES = 450


def _modules() -> dict[str, Path]:
    """Module name → file, for every module of the package."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict) -> list[tuple[str, str, int]]:
    """(imported module, imported name or "", line) of every optipose import in a module, wherever it is."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(alias.name, "", node.lineno) for alias in node.names if alias.name.split(".")[0] == "optipose"]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package, one level up per extra dot
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            if base.split(".")[0] != "optipose":
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                out.append((sub, "", node.lineno) if sub in modules else (base, alias.name, node.lineno))
    return out


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {
        name: {target for target, _, _ in _imports(name, path, modules) if target in modules and target != name}
        for name, path in modules.items()
    }


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, out, counter = {}, {}, set(), [], [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return out


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_between_modules():
    assert _cycles(_graph()) == []


def test_no_module_over_450_lines():
    long = {name: n for name, path in _modules().items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_no_private_name_imported_from_another_module():
    modules = _modules()
    private = [
        f"{path.relative_to(ROOT.parent)}:{line}: {target}.{what}"
        for name, path in modules.items()
        for target, what, line in _imports(name, path, modules)
        if what.startswith("_") and not what.startswith("__") and target != name
    ]
    assert private == []


VERDICT = "optipose.verdict"


def _defined(path: Path) -> set[str]:
    """The names a module defines at its top level itself (functions, classes, assignments), not those it imports."""
    out = set()
    for node in ast.parse(path.read_text(), str(path)).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            out |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return out


def _verdict_names() -> set[str]:
    """The public names of optipose.verdict's modules (what each defines without a leading _)."""
    return {
        name
        for module, path in _modules().items()
        if module.startswith(VERDICT + ".")
        for name in _defined(path)
        if not name.startswith("_")
    }


def _reexported_verdict_imports(files: list[Path], names: set[str]) -> list[str]:
    """``file:line: module.name`` of every import of a verdict name from an optipose module outside the verdict
    package that does not define it itself (a module that re-exports it); a namesake defined there is its own."""
    modules, out = _modules(), []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ImportFrom) or node.level or not (node.module or "").startswith("optipose"):
                continue
            source = node.module
            if source == VERDICT or source.startswith(VERDICT + ".") or source not in modules:
                continue
            own = _defined(modules[source])
            out += [
                f"{path}:{node.lineno}: {source}.{alias.name}"
                for alias in node.names
                if alias.name in names and alias.name not in own
            ]
    return out


def test_the_verdict_is_imported_from_its_own_package():
    """Every import of a verdict name (Decision, ConfidentVerdict, Verdicts, Verdict, Rules, race, the words …) comes
    from an optipose.verdict module, in the library, the tests, the benchmarks and the scripts: never through a
    package that re-exports it."""
    names = _verdict_names()
    assert {"Decision", "ConfidentVerdict", "Verdicts", "Verdict", "Rules", "race", "confident_line"} <= names
    files = [
        f for name in ("optipose", "tests", "benchmarks", "scripts") for f in sorted((ROOT.parent / name).rglob("*.py"))
    ]
    assert _reexported_verdict_imports(files, names) == []


def test_the_verdict_import_check_finds_a_re_export(tmp_path):
    """optipose.io.results imports Verdict for its own records: importing Verdict from there is a re-export."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "from optipose.io.results import SearchResult, Verdict\nfrom optipose.verdict.compare import bought\n"
    )
    assert _reexported_verdict_imports([bad], _verdict_names()) == [f"{bad}:1: optipose.io.results.Verdict"]


def test_the_code_is_formatted():
    """ruff format (its settings in pyproject.toml) leaves every file as it is."""
    import subprocess
    import sys

    ruff = Path(sys.executable).with_name("ruff")
    roots = [str(ROOT.parent / name) for name in ("optipose", "tests", "benchmarks", "scripts")]
    done = subprocess.run([str(ruff), "format", "--check", *roots], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
