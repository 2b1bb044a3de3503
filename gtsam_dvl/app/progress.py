"""The command line's progress bar (rich) around the core's plain progress callback (core/progress.py)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from gtsam_dvl.core.progress import ProgressFn


@contextmanager
def progress_bar(description: str, enabled: bool = True) -> Iterator[ProgressFn]:
    """A rich progress bar on stderr, yielded as a callback taking the fraction done."""
    if not enabled:
        yield lambda _fraction: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    # stderr: stdout carries the results only, so that a redirected run's output holds no progress bars
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        transient=False,
        console=Console(stderr=True),
    ) as bar:
        task = bar.add_task(description, total=1.0)
        yield lambda fraction: bar.update(task, completed=min(max(fraction, 0.0), 1.0))
        bar.update(task, completed=1.0)
