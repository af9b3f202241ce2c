"""The package layers of ARCHITECTURE.md hold: every import goes down (or sideways), no cycles.

The layer table is read from ARCHITECTURE.md itself, so the document and the code
cannot drift apart: a new package must be placed there before it can be imported.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "dgse"


def layer_table() -> dict[str, int]:
    """Package -> layer number, from the rows ``| N name | `pkg`, `pkg` | ...`` of ARCHITECTURE.md."""
    text = (ROOT / "ARCHITECTURE.md").read_text()
    section = text.split("## Layers and import direction", 1)[1].split("\n## ", 1)[0]
    layers: dict[str, int] = {}
    for line in section.splitlines():
        m = re.match(r"^\|\s*(\d+)\b[^|]*\|([^|]*)\|", line)
        if m:
            for pkg in re.findall(r"`([a-z_]+)`", m.group(2)):
                assert pkg not in layers, f"{pkg} is in two layers of ARCHITECTURE.md"
                layers[pkg] = int(m.group(1))
    return layers


def package_of(module: str) -> str:
    """``dgse.a.b`` -> ``a``; ``dgse`` -> ``""``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def module_name(path: Path) -> str:
    rel = path.relative_to(SRC.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of every ``dgse`` import in a file, at any depth (lazy ones too)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "dgse"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] == "dgse":
                if node.module == "dgse":  # `from dgse import errors`: each name is a module
                    out += [(node.lineno, f"dgse.{a.name}") for a in node.names]
                else:
                    out.append((node.lineno, node.module))
        elif isinstance(node, ast.ImportFrom) and node.level > 0:
            out.append((node.lineno, "<relative>"))
    return out


def package_edges() -> dict[tuple[str, str], list[str]]:
    """(importing package, imported package) -> where (``file:line``), between different packages."""
    edges: dict[tuple[str, str], list[str]] = {}
    for path in sorted(SRC.rglob("*.py")):
        src = package_of(module_name(path))
        for line, mod in imports_of(path):
            assert mod != "<relative>", f"{path.relative_to(ROOT)}:{line}: use absolute imports"
            dst = package_of(mod)
            if src and dst and src != dst:
                edges.setdefault((src, dst), []).append(f"{path.relative_to(ROOT)}:{line}")
    return edges


def test_every_package_has_a_layer() -> None:
    layers = layer_table()
    packages = {p.stem if p.is_file() else p.name for p in SRC.iterdir()}
    packages = {p for p in packages if not p.startswith(("_", ".")) and p not in ("assets", "py")}
    packages = {p for p in packages if (SRC / p).is_dir() and (SRC / p / "__init__.py").exists()} | {
        p.stem for p in SRC.glob("*.py") if p.stem != "__init__"
    }
    missing = sorted(packages - set(layers))
    assert not missing, f"packages not placed in ARCHITECTURE.md's layer table: {missing}"
    stale = sorted(set(layers) - packages)
    assert not stale, f"ARCHITECTURE.md places packages that do not exist: {stale}"


def test_imports_go_down_the_layers() -> None:
    layers = layer_table()
    bad = [
        f"{where[0]}: {src} (layer {layers[src]}) imports {dst} (layer {layers[dst]})"
        + (f" and {len(where) - 1} more" if len(where) > 1 else "")
        for (src, dst), where in sorted(package_edges().items())
        if layers.get(dst, -1) > layers.get(src, -1)
    ]
    assert not bad, "imports against ARCHITECTURE.md's layer order:\n" + "\n".join(bad)


def test_no_cycle_between_packages() -> None:
    graph: dict[str, set[str]] = {}
    for src, dst in package_edges():
        graph.setdefault(src, set()).add(dst)
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycle = [*stack[stack.index(nxt) :], nxt]
                pytest.fail("import cycle between packages: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)


def test_the_checker_sees_an_upward_import(tmp_path: Path) -> None:
    """The import walker finds lazy imports inside functions and `from dgse import x` forms."""
    f = tmp_path / "m.py"
    f.write_text(
        "def f():\n    from dgse.cli.main import main\n    import dgse.bench\nfrom dgse import errors\n"
    )
    assert {m for _, m in imports_of(f)} == {"dgse.cli.main", "dgse.bench", "dgse.errors"}
