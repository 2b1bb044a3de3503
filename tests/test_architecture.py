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
    "core": {
        "factors"
    },  # core.rotations: the SO(3) helpers of factors/so3.py (factors imports no gtsam_dvl)
    "factors": set(),
    "sim": {"core"},
    "estimators": {"core", "factors"},
    "analysis": {"core", "factors", "estimators", "sim"},
    "io": {"core"},
    "app": {"core", "factors", "estimators", "analysis", "sim", "io"},
}
FORBIDDEN_THIRD_PARTY = {
    "core": {"matplotlib", "typer", "rich"},
    "factors": {"matplotlib", "typer", "rich"},
    "sim": {"matplotlib", "typer", "rich"},
    "estimators": {"matplotlib", "typer", "rich"},
    "analysis": {"matplotlib", "typer", "rich"},
}


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
            raise AssertionError(
                f"{path}:{node.lineno}: relative import outside factors/"
            )  # pragma: no cover
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
            mods = [
                (n.lineno, n.module or "")
                for n in ast.walk(tree)
                if isinstance(n, ast.ImportFrom) and n.level == 0
            ]
            mods += [
                (n.lineno, a.name)
                for n in ast.walk(tree)
                if isinstance(n, ast.Import)
                for a in n.names
            ]
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
    src.write_text(
        "def f():\n    from gtsam_dvl.io.reader import read_log\n    import matplotlib.pyplot\n"
    )
    assert [m for _, m in _imports(src)] == ["gtsam_dvl.io.reader", "matplotlib.pyplot"]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PKG.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_imports(path: Path) -> list[str]:
    """The gtsam_dvl modules a file imports at run time, lazy ones inside functions included; the imports under
    `if TYPE_CHECKING:` (annotations only, never executed) left out. `from a.b import c` counts as a.b.c when that
    is a module, else as a.b."""
    tree = ast.parse(path.read_text(), str(path))
    skip: set[int] = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.If)
            and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING"
        ):
            skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out += [f"{node.module}.{a.name}" for a in node.names]
    return [m for m in out if m.startswith("gtsam_dvl")]


def import_cycles(files: dict[str, Path]) -> list[list[str]]:
    """The import cycles among the modules (name -> file): the strongly connected components of more than one
    module of the import graph (Tarjan's algorithm, by hand: a dozen lines, no graph library in the test set)."""

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    edges = {
        m: {t for imp in _runtime_imports(p) if (t := resolve(imp)) and t != m}
        for m, p in files.items()
    }
    # a module importing its own package's __init__ (or a package its submodule) is not a cycle of design
    edges = {
        m: {t for t in ts if not m.startswith(t + ".") and not t.startswith(m + ".")}
        for m, ts in edges.items()
    }
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(files):
        if v not in index:
            visit(v)
    return cycles


def _package_files() -> dict[str, Path]:
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    # a symlink to the top-level factors/ (pyproject.toml), which rglob does not follow
    factors = PKG / "factors"
    files |= {
        "gtsam_dvl.factors." + p.stem if p.stem != "__init__" else "gtsam_dvl.factors": p
        for p in sorted(factors.resolve().glob("*.py"))
    }
    return files


def test_no_import_cycle() -> None:
    """No module imports, even lazily inside a function, a module that imports it back (directly or through
    others): such a cycle hides an order of initialisation that one moved import breaks."""
    cycles = import_cycles(_package_files())
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_the_cycle_check_sees_a_lazy_cycle(tmp_path: Path) -> None:
    root = tmp_path / "gtsam_dvl"
    root.mkdir()
    (root / "a.py").write_text("def f():\n    from gtsam_dvl.b import g\n")
    (root / "b.py").write_text("from gtsam_dvl.a import f\n")
    (root / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from gtsam_dvl.a import f\n"
    )
    (root / "d.py").write_text("from gtsam_dvl.c import x\n")
    files = {"gtsam_dvl." + p.stem: p for p in root.glob("*.py")}
    assert import_cycles(files) == [["gtsam_dvl.a", "gtsam_dvl.b"]]


ESTIMATOR_STAGES = (
    "inputs",
    "models",
    "graph",
)  # estimators/ before any estimator (docs/architecture.md)
ESTIMATOR_FOLDERS = ("batch", "online", "ekf")


def _stage_of(module: str) -> str | None:
    """The folder (or top-level module) of estimators/ a module is in: "inputs", "batch", "run", ..."""
    parts = module.split(".")
    return parts[2] if parts[:2] == ["gtsam_dvl", "estimators"] and len(parts) > 2 else None


def stage_violations(files: dict[str, Path]) -> list[str]:
    """Imports across estimators/ against its stages (test below), one line each."""
    bad = []
    for name, path in files.items():
        own = _stage_of(name)
        for imported in _runtime_imports(path) if own is not None else []:
            other = _stage_of(imported)
            if other is None or other == own:
                continue
            if own in ESTIMATOR_STAGES and other not in ESTIMATOR_STAGES:
                bad.append(f"{name} (a stage) imports {imported}")
            if own in ESTIMATOR_FOLDERS and other in ESTIMATOR_FOLDERS:
                bad.append(f"{name} imports another estimator's {imported}")
    return bad


def test_estimator_stages_import_no_estimator() -> None:
    """estimators/ by stage: inputs, models and graph import no estimator (batch, online, ekf, iodvlc, the runner),
    and no estimator's folder imports another's, lazily or not (type-only imports aside)."""
    bad = stage_violations(_package_files())
    assert not bad, "\n".join(bad)


def test_the_stage_check_sees_violations(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text(
        "def f():\n    from gtsam_dvl.estimators.batch.smoother import g\n"
    )
    (tmp_path / "b.py").write_text("from gtsam_dvl.estimators.online.types import x\n")
    (tmp_path / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from gtsam_dvl.estimators.ekf import y\n"
    )
    files = {
        "gtsam_dvl.estimators.models.a": tmp_path / "a.py",
        "gtsam_dvl.estimators.ekf.b": tmp_path / "b.py",
        "gtsam_dvl.estimators.graph.c": tmp_path / "c.py",
    }
    assert stage_violations(files) == [
        "gtsam_dvl.estimators.models.a (a stage) imports gtsam_dvl.estimators.batch.smoother.g",
        "gtsam_dvl.estimators.ekf.b imports another estimator's gtsam_dvl.estimators.online.types.x",
    ]
