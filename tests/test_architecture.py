"""The package layout that docs/architecture.md draws is the code's: imports point down the
package order only, no module imports one that imports it back, and every module the
package table names exists in the package that the table says holds it."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "ros_ws" / "src"
#: Bottom to top: a package may import only those before it.
ORDER = ("hexapod_common", "hexapod_sim", "hexapod_control", "hexapod_metrics",
         "hexapod_bringup")


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for every package's Python sources."""
    out = {}
    for pkg in ORDER:
        base = SRC / pkg
        for f in (base / pkg).rglob("*.py"):
            parts = list(f.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def _imports(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """Project modules that module ``name`` imports (relative imports resolved)."""
    tree = ast.parse(path.read_text())
    pkg_parts = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg_parts[:len(pkg_parts) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [mod] + [f"{mod}.{a.name}" for a in node.names]
        else:
            continue
        for t in targets:
            if t in known and t != name:
                found.add(t)
    return found


def test_imports_point_down_the_package_order_only() -> None:
    known = _modules()
    upward = []
    for name, path in known.items():
        level = ORDER.index(name.split(".")[0])
        for dep in _imports(name, path, known):
            if ORDER.index(dep.split(".")[0]) > level:
                upward.append(f"{name} -> {dep}")
    assert upward == []


def test_no_module_imports_one_that_imports_it_back() -> None:
    known = _modules()
    graph = {n: _imports(n, p, known) - {n} for n, p in known.items()}
    # packages' __init__ re-exports are edges too; a cycle through them is still a cycle
    state: dict[str, int] = {}
    cycles = []

    def visit(n: str, stack: list[str]) -> None:
        state[n] = 1
        for d in sorted(graph[n]):
            if state.get(d) == 1:
                cycles.append(stack[stack.index(d):] + [d] if d in stack else [n, d])
            elif d not in state:
                visit(d, stack + [d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    # a package importing its own submodule is not a cycle unless the submodule imports back
    real = [c for c in cycles if not all(a.startswith(b + ".") or b.startswith(a + ".")
                                         for a, b in zip(c, c[1:]))]
    assert real == []


def test_the_package_table_of_the_architecture_doc_matches_the_code() -> None:
    doc = (ROOT / "docs" / "architecture.md").read_text()
    rows = [ln for ln in doc.splitlines() if re.match(r"\| `hexapod_\w+` \|", ln)]
    assert [re.match(r"\| `(\w+)`", r).group(1) for r in rows] == list(ORDER)  # type: ignore[union-attr]
    for row in rows:
        pkg = re.match(r"\| `(\w+)`", row).group(1)  # type: ignore[union-attr]
        holds = row.split("|")[2]
        base = SRC / pkg / pkg
        section = ""
        named = re.findall(r"`(core/|runtime/|bag/|config/hexapod\.yaml|[\w/]+\.py)`", holds)
        assert named, row
        for item in named:
            if item.endswith("/"):
                section = item
                assert (base / item).is_dir(), f"{pkg}: no {item}"
                continue
            if item.startswith("config/"):
                assert (SRC / pkg / item).is_file(), f"{pkg}: no {item}"
                continue
            where = [base / item, base / section / item]
            assert any(w.is_file() for w in where), f"{pkg}: no {item} (in {section or '.'})"
