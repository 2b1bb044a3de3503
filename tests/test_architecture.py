"""The layers of the package (docs/architecture.md), checked on the import graph of the source itself.

Every import counts, including those inside functions (lazy imports for a fast `--help`): a layer may import
only the layers below it. core at the bottom; factors beside it; sim, estimators and analysis above; io and
app at the edges. No module of the core layers draws (matplotlib) or touches files (io)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "gtsam_dvl"

# what each layer may import from the package (besides itself)
ALLOWED = {
    "core": {"factors"},  # core.rotations: the SO(3) helpers of factors/so3.py (factors imports no gtsam_dvl)
    "factors": set(),
    "sim": {"core"},
    "estimators": {"core", "factors"},
    "analysis": {"core", "factors", "estimators", "sim"},
    "io": {"core"},
    "app": {"core", "factors", "estimators", "analysis", "sim", "io"},
}
FORBIDDEN_THIRD_PARTY = {"core": {"matplotlib", "typer", "rich"}, "factors": {"matplotlib", "typer", "rich"},
                         "sim": {"matplotlib", "typer", "rich"}, "estimators": {"matplotlib", "typer", "rich"},
                         "analysis": {"matplotlib", "typer", "rich"}}


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), str(path))
    out: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
            if node.module == "gtsam_dvl":  # from gtsam_dvl import core, io, ...
                out += [(node.lineno, f"gtsam_dvl.{a.name}") for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level > 0:
            raise AssertionError(f"{path}:{node.lineno}: relative import outside factors/")  # pragma: no cover
    return out


def _layer_files() -> list[tuple[str, Path]]:
    files = []
    for layer in ALLOWED:
        root = PKG / layer
        assert root.is_dir(), f"layer {layer} missing"
        files += [(layer, p) for p in sorted(root.rglob("*.py"))]
    return files


def test_every_module_belongs_to_a_layer() -> None:
    top = sorted(p.name for p in PKG.glob("*.py"))
    assert top == ["__init__.py"], f"modules outside the layers: {top}"


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layer_imports_only_the_layers_below(layer: str) -> None:
    bad = []
    for lay, path in _layer_files():
        if lay != layer:
            continue
        if layer == "factors":  # factors use relative imports among themselves
            source = path.read_text()
            tree = ast.parse(source)
            mods = [(n.lineno, n.module or "") for n in ast.walk(tree)
                    if isinstance(n, ast.ImportFrom) and n.level == 0]
            mods += [(n.lineno, a.name) for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        else:
            mods = _imports(path)
        for line, mod in mods:
            parts = mod.split(".")
            if parts[0] == "gtsam_dvl" and len(parts) > 1 and parts[1] != layer:
                if parts[1] not in ALLOWED[layer] and parts[1] != "__version__":
                    bad.append(f"{path.relative_to(PKG)}:{line} imports {mod}")
            if parts[0] in FORBIDDEN_THIRD_PARTY.get(layer, set()):
                bad.append(f"{path.relative_to(PKG)}:{line} imports {mod}")
    assert not bad, "\n".join(bad)


def test_the_check_sees_a_violation(tmp_path: Path) -> None:
    """The parser finds lazy imports inside functions (what a layering violation usually looks like)."""
    src = tmp_path / "m.py"
    src.write_text("def f():\n    from gtsam_dvl.io.reader import read_log\n    import matplotlib.pyplot\n")
    assert [m for _, m in _imports(src)] == ["gtsam_dvl.io.reader", "matplotlib.pyplot"]
