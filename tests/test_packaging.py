"""What a user installs: `pip install .` or a wheel, never the editable install every other test runs against.

A hand-kept package list once left four subpackages (31 modules) out of the wheel, and `gtsam-dvl smooth` from a
wheel ended in ModuleNotFoundError while every test passed. Two checks:
- fast: every package folder of the source tree (followed through the factors and scenarios symlinks) is a package
  the build finds, and every data file under the package is shipped by a package-data pattern;
- slow: the wheel is built (offline, with the test environment's setuptools), installed without its dependencies
  into a scratch folder that shadows the editable install, and its console script runs simulate, smooth (batch,
  online, ekf), evaluate and plan as subprocesses; then every module of the installed package imports.
"""

from __future__ import annotations

import fnmatch
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "gtsam_dvl"
# what a build reads besides the package: the project's metadata and the symlinks' targets
BUILD_INPUTS = ("pyproject.toml", "README.md", "gtsam_dvl", "factors", "data/scenarios")


def tree_packages() -> dict[str, Path]:
    """Every folder under gtsam_dvl/ holding Python modules, by dotted name (symlinked folders followed)."""
    found = {}
    for folder, dirs, files in os.walk(PACKAGE, followlinks=True):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        if any(f.endswith(".py") for f in files):
            rel = Path(folder).relative_to(ROOT)
            found[".".join(rel.parts)] = Path(folder)
    return found


def build_configuration() -> tuple[list[str], dict[str, list[str]]]:
    """The packages and package data that setuptools takes from pyproject.toml (its own discovery, run here)."""
    from setuptools.config.pyprojecttoml import apply_configuration
    from setuptools.dist import Distribution

    cwd = Path.cwd()
    os.chdir(ROOT)  # the discovery's `where` is relative to the project
    try:
        dist = apply_configuration(Distribution(), ROOT / "pyproject.toml")
    finally:
        os.chdir(cwd)
    return list(dist.packages or []), dict(dist.package_data or {})


def test_every_package_folder_ships() -> None:
    packages, _ = build_configuration()
    tree = tree_packages()
    assert (
        "gtsam_dvl.factors" in tree and "gtsam_dvl.scenarios" in tree
    )  # the symlinks are followed
    missing = sorted(set(tree) - set(packages))
    extra = sorted(set(packages) - set(tree))
    assert not missing, f"package folders a build would leave out: {missing}"
    assert not extra, f"packages a build would ship that are no folder of the tree: {extra}"
    no_init = sorted(
        name for name, folder in tree.items() if not (folder / "__init__.py").is_file()
    )
    assert not no_init, f"package folders without __init__.py: {no_init}"


def test_every_data_file_ships() -> None:
    """A file under the package that is not Python (a scenario, the presets, the live layout, a message
    definition) is read by a command at run time: a package-data pattern of its package must ship it."""
    packages, package_data = build_configuration()
    tree = tree_packages()
    unshipped = []
    for folder, dirs, files in os.walk(PACKAGE, followlinks=True):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for name in files:
            if name.endswith((".py", ".pyc")):
                continue
            path = Path(folder) / name
            # the owning package: the nearest folder up that is a package
            owner = Path(folder)
            while ".".join(owner.relative_to(ROOT).parts) not in tree:
                owner = owner.parent
            pkg = ".".join(owner.relative_to(ROOT).parts)
            rel = path.relative_to(owner).as_posix()
            patterns = (
                package_data.get(pkg, []) + package_data.get("", []) + package_data.get("*", [])
            )
            if pkg not in packages or not any(fnmatch.fnmatch(rel, p) for p in patterns):
                unshipped.append(f"{pkg}: {rel}")
    assert not unshipped, f"data files no package-data pattern ships: {unshipped}"
    # the files the commands read are among them (a test that would pass on an empty package is no test)
    shipped = {f"{p}/{pat}" for p, pats in package_data.items() for pat in pats}
    for expected in ("gtsam_dvl.scenarios/*.toml", "gtsam_dvl.core.config/presets.toml"):
        assert expected in shipped


def run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: float = 600) -> str:
    """Run one command; its whole output in the failure message when it fails or prints a traceback."""
    proc = subprocess.run(
        cmd,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"{' '.join(cmd[-4:])}: exit {proc.returncode}\n{out[-4000:]}"
    assert "Traceback" not in out, out[-4000:]
    return out


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """The wheel built from a copy of the build's inputs (so that no build/ or egg-info lands in the checkout)
    and installed with --target: its folder first on PYTHONPATH shadows the editable install."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    for name in BUILD_INPUTS:
        origin = ROOT / name
        ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
        if origin.is_dir():
            shutil.copytree(origin, src / name, symlinks=True, ignore=ignore)
        else:
            src.joinpath(name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(origin, src / name)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    pip = [sys.executable, "-m", "pip"]
    run(
        [
            *pip,
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "-w",
            str(base / "dist"),
            str(src),
        ],
        base,
        env,
    )
    (wheel,) = (base / "dist").glob("gtsam_dvl-*.whl")
    target = base / "target"
    run(
        [*pip, "install", "-q", "--no-deps", "--no-index", "--target", str(target), str(wheel)],
        base,
        env,
    )
    env["PYTHONPATH"] = str(target)
    return target, env


@pytest.mark.slow
def test_wheel_commands_run(installed: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    target, env = installed
    cli = [str(target / "bin" / "gtsam-dvl")]  # the console script the wheel installs
    where = run(
        [sys.executable, "-c", "import gtsam_dvl, gtsam_dvl.factors; print(gtsam_dvl.__file__)"],
        tmp_path,
        env,
    )
    assert Path(where.strip()).is_relative_to(target), f"not the wheel's package: {where}"
    run([*cli, "simulate", "paper-3d-short", "-o", "a.mcap", "-q"], tmp_path, env)
    for mode in ("batch", "online", "ekf"):
        run(
            [
                *cli,
                "smooth",
                "a.mcap",
                "--mode",
                mode,
                "-o",
                f"r-{mode}.mcap",
                "--summary",
                f"s-{mode}.json",
                "-q",
            ],
            tmp_path,
            env,
        )
        summary = json.loads((tmp_path / f"s-{mode}.json").read_text())
        assert summary["health"]["status"] != "failed", (mode, summary["health"])
        # the log's truth is known: the scale (ppm) within 3 sigma of the estimate's own marginal
        errors = summary["errors"]
        assert abs(errors["scale_nsigma"]) < 3, (mode, errors["scale_nsigma"])
        assert errors["final_horizontal_position_pct_distance"] < 1.0, (mode, errors)
    run([*cli, "evaluate", "r-batch.mcap", "-o", "eval"], tmp_path, env)
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert metrics, "evaluate wrote an empty metrics.json"
    run([*cli, "plan", "paper-3d-short", "-o", "plan", "-q"], tmp_path, env)
    plan = json.loads((tmp_path / "plan" / "plan.json").read_text())
    assert plan["scenario"] == "paper-3d-short" and plan["answer"]


@pytest.mark.slow
def test_wheel_imports_every_module(installed: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    """Every module of the installed package imports (the optional extras' modules too: the test environment has
    them), and the front door's names resolve."""
    target, env = installed
    code = (
        "import importlib, pkgutil, gtsam_dvl\n"
        "names = [m.name for m in pkgutil.walk_packages(gtsam_dvl.__path__, 'gtsam_dvl.')]\n"
        "for n in names: importlib.import_module(n)\n"
        "for n in gtsam_dvl.__all__: getattr(gtsam_dvl, n)\n"
        "print(len(names))\n"
    )
    out = run([sys.executable, "-c", code], tmp_path, env)
    expected = (
        sum(
            1
            for folder in tree_packages().values()
            for f in folder.iterdir()
            if f.suffix == ".py" and f.name != "__init__.py"
        )
        + len(tree_packages())
        - 1
    )  # every module and every subpackage, less gtsam_dvl itself
    assert int(out.strip().splitlines()[-1]) == expected
