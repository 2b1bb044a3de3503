"""Atomic file writes: a temporary file in the target folder, then a rename, so that an interrupted
run never leaves a half-written result under its final name."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def atomic_write_bytes(path: Path | str, data: bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: Path | str, text: str) -> Path:
    return atomic_write_bytes(path, text.encode())


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_json(data: Any) -> str:
    return json.dumps(data, indent=2, default=_json_default, allow_nan=True)


def atomic_write_json(path: Path | str, data: Any) -> Path:
    return atomic_write_text(path, to_json(data) + "\n")


def write_tum(path: Path | str, t_abs_s: np.ndarray, n_p: np.ndarray, n_q_b_xyzw: np.ndarray) -> Path:
    """TUM trajectory file (t x y z qx qy qz qw per line), as evo reads it."""
    rows = np.column_stack([t_abs_s, n_p, n_q_b_xyzw])
    lines = "\n".join(" ".join(f"{v:.9f}" if j == 0 else f"{v:.9g}" for j, v in enumerate(r)) for r in rows)
    return atomic_write_text(path, lines + "\n")
