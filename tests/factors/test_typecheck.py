"""mypy sees the factors' signatures at every call site (gtsam_dvl.factors is a real package path, the
symlink gtsam_dvl/factors -> ../factors): a call with a wrong argument type fails the type check that
`make test` runs, instead of failing at run time inside GTSAM."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CALL = """
import gtsam
import numpy as np

from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, V, X
from gtsam_dvl.factors import make_dvl_velocity_factor

noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.02)
factor = make_dvl_velocity_factor(noise, X(0), V(0), K_SCALE, C_MISALIGN, {d_y}, np.zeros(3), np.zeros(3))
reveal_type(make_dvl_velocity_factor)
"""


def _mypy(tmp_path: Path, d_y: str) -> subprocess.CompletedProcess[str]:
    src = tmp_path / "call_site.py"
    src.write_text(CALL.format(d_y=d_y))
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            # incremental, in the project's cache (`make test` runs `mypy gtsam_dvl` first): the package's
            # modules are read from it, and only the call site is checked again
            "--config-file",
            str(ROOT / "pyproject.toml"),
            str(src),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.skipif(
    shutil.which("mypy") is None and not (Path(sys.executable).parent / "mypy").exists(),
    reason="mypy not installed",
)
def test_wrong_argument_type_at_a_factor_call_fails_mypy(tmp_path: Path) -> None:
    good = _mypy(tmp_path, "np.array([1.0, 0.0, 0.0])")
    print(good.stdout)
    revealed = good.stdout.split("Revealed type is")[1].split("\n")[0]
    # not Any
    assert revealed.startswith(' "def (noise: gtsam') and "d_y: numpy.ndarray" in revealed
    assert good.returncode == 0, good.stdout
    bad = _mypy(tmp_path, '"fast"')  # a string where the DVL velocity (ndarray) belongs
    print(bad.stdout)
    assert bad.returncode != 0
    assert 'Argument 6 to "make_dvl_velocity_factor" has incompatible type "str"' in bad.stdout
