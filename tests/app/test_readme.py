"""The README's Python examples run as written (on a simulated log named as they expect)."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from gtsam_dvl.app.commands import simulate_to_file, smooth_file

ROOT = Path(__file__).resolve().parents[2]


def test_readme_python_blocks_run(tmp_path: Path) -> None:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert blocks, "no Python example in the README"
    simulate_to_file("paper-2d", tmp_path / "run.mcap", seed=3, show_progress=False)
    smooth_file(
        tmp_path / "run.mcap", tmp_path / "result.mcap", show_progress=False, timeline=False
    )
    cwd = os.getcwd()
    os.chdir(tmp_path)
    namespaces: list[dict[str, Any]] = []
    try:
        for code in blocks:
            namespaces.append({})
            exec(compile(code, "README.md", "exec"), namespaces[-1])  # noqa: S102 - the README's own code
    finally:
        os.chdir(cwd)
    # the first block smooths the paper-2d log: its scale within 4 sigma of the truth, and the stored result
    # read back is the one smoothed by the command (same estimator, same numbers)
    first = namespaces[0]
    result, stored = first["result"], first["stored"]
    assert abs(result.scale - 0.9998) < 4 * result.scale_sigma
    assert abs(stored.result.scale - result.scale) < 1e-3 * result.scale_sigma
