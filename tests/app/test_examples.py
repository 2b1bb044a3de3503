"""The example study runs and its numbers make physical sense."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]


def test_descent_study_quick(tmp_path: Path) -> None:
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "descent_study.py"),
            "-o",
            str(tmp_path),
            "--quick",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    print(proc.stdout)
    rows = {
        (float(r["dvl_hz"]), float(r["descent_s"])): float(r["roll_sigma_deg"])
        for r in csv.DictReader(open(tmp_path / "descent_study.csv"))
    }
    # no descent: the prior (1 deg) stays
    assert rows[(1.0, 0.0)] > 0.99 and rows[(2.0, 0.0)] > 0.99
    assert rows[(1.0, 60.0)] < 0.5  # a 60 s descent determines it
    assert rows[(2.0, 60.0)] < rows[(1.0, 60.0)]  # more pings, more information
    assert (tmp_path / "descent_study.png").stat().st_size > 10_000
