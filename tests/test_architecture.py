"""The house rules of the layout, checked on the source with ``ast`` (nothing is imported).

* no import circle between modules of the four packages (every import counts, module-level or
  inside a function, since a lazy import that closes a circle is still a circle in the design);
* dependencies point one way: ``wpt_receiver`` <- ``mission_sim`` <- ``envs`` <- ``policies``; only
  ``mission_sim.cli`` reaches ``envs``/``policies`` (lazily, inside its subcommands), and the sweep's
  mission runner may build a policy by name (lazily);
* plotting (matplotlib, ``mission_sim.figures``) is imported only by :data:`PLOTTING_ALLOWED`;
* no function longer than 80 lines outside tests and benchmarks;
* every package's ``__init__.py`` docstring is a map: it names each of its modules and subpackages.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("wpt_receiver", "mission_sim", "envs", "policies")
RANK = {"wpt_receiver": 0, "mission_sim": 1, "envs": 2, "policies": 3}
MAX_FUNCTION_LINES = 80
#: the modules that may draw: figures, the CLI, reports of results and the env's render
PLOTTING_ALLOWED = ("mission_sim.figures", "mission_sim.cli", "mission_sim.studies.report", "envs.render",
                    "policies.compare", "policies.train")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = path
    return mods


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, int, bool]]:
    """Modules of ours that ``name`` imports: (module, line, at module level)."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    tree = ast.parse(path.read_text(), str(path))
    top = {id(n) for n in tree.body}
    for n in tree.body:   # module-level try/if blocks still run at import time
        if isinstance(n, (ast.Try, ast.If)):
            top.update(id(c) for c in ast.walk(n))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                root = base[:len(base) - node.level + 1]
                mod = ".".join(root + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        for t in targets:
            # the longest prefix that is one of our modules
            parts = t.split(".")
            for k in range(len(parts), 0, -1):
                cand = ".".join(parts[:k])
                if cand in MODULES:
                    if cand != name:
                        out.append((cand, node.lineno, id(node) in top))
                    break
    return out


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def test_no_import_circles():
    """Tarjan's strongly connected components over every import (lazy ones included)."""
    edges = {m: sorted({t for t, _, _ in GRAPH[m]}) for m in GRAPH}
    index, low, stack, on, sccs = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert not sccs, f"import circles: {sccs}"


def test_dependencies_point_one_way():
    bad = []
    for m, imps in GRAPH.items():
        pkg = m.split(".")[0]
        for t, line, _ in imps:
            tp = t.split(".")[0]
            if RANK[tp] <= RANK[pkg]:
                continue
            if m.startswith("mission_sim.cli") or m == "mission_sim.studies.sweep":
                continue   # the CLI (and the sweep's policy-by-name) reach up lazily, checked below
            bad.append(f"{MODULES[m].relative_to(ROOT)}:{line} imports {t}")
    assert not bad, "imports against the dependency direction:\n" + "\n".join(bad)


def test_cli_reaches_envs_and_policies_only_lazily():
    eager = [f"{m}:{line} -> {t}" for m, imps in GRAPH.items() if m.startswith("mission_sim")
             for t, line, top in imps if top and t.split(".")[0] in ("envs", "policies")]
    assert not eager, f"module-level imports of envs/policies from mission_sim: {eager}"


def test_plotting_never_imported_by_physics():
    bad = []
    for m, path in MODULES.items():
        if m.startswith(PLOTTING_ALLOWED):
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
            if any(n.split(".")[0] == "matplotlib" for n in names):
                bad.append(f"{m}:{node.lineno} imports matplotlib")
        bad += [f"{m}:{line} imports {t}" for t, line, _ in GRAPH[m] if t.startswith("mission_sim.figures")]
    assert not bad, bad


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_function_longer_than_80_lines(pkg):
    long = []
    for path in sorted((ROOT / pkg).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "functions over 80 lines:\n" + "\n".join(long)


def _package_dirs():
    return [d for pkg in PACKAGES for d in [ROOT / pkg, *(ROOT / pkg).rglob("*")]
            if d.is_dir() and (d / "__init__.py").is_file()]


@pytest.mark.parametrize("pkg_dir", _package_dirs(), ids=lambda d: str(d.relative_to(ROOT)))
def test_each_package_docstring_is_a_map(pkg_dir):
    doc = ast.get_docstring(ast.parse((pkg_dir / "__init__.py").read_text())) or ""
    names = [p.stem for p in pkg_dir.glob("*.py") if p.stem != "__init__"]
    names += [d.name + "/" for d in pkg_dir.iterdir() if (d / "__init__.py").is_file()]
    missing = [n for n in sorted(names) if f"``{n}``" not in doc and f"``{n.rstrip('/')}``" not in doc]
    assert not missing, f"{pkg_dir.relative_to(ROOT)}/__init__.py docstring does not name {missing}"


def test_no_merge_conflict_leftovers():
    texts = {p: p.read_text() for p in [*MODULES.values(), *ROOT.glob("*.md"), *(ROOT / "docs").glob("*.md")]}
    bad = [str(p.relative_to(ROOT)) for p, t in texts.items()
           if any(ln.startswith(("<<<<<<< ", ">>>>>>> ")) or ln == "=======" for ln in t.splitlines())]
    assert not bad, bad


def test_the_checker_sees_a_circle(tmp_path):
    """The circle check can fail: two modules that import each other form a component."""
    global GRAPH
    saved = GRAPH
    GRAPH = {**saved, "wpt_receiver.params": saved["wpt_receiver.params"] + [("wpt_receiver.envelope", 1, True)]}
    try:
        with pytest.raises(AssertionError, match="circle"):
            test_no_import_circles()
    finally:
        GRAPH = saved
