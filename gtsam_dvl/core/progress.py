"""Progress reporting: the core takes a plain callback; the command line turns it into a progress bar
(gtsam_dvl/app/progress.py)."""

from __future__ import annotations

from collections.abc import Callable

ProgressFn = Callable[[float], None]  # fraction done in [0, 1]
