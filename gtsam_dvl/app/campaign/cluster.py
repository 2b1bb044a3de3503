"""The Dask client of a campaign or a fleet: dask.distributed, not a home-made pool. A LocalCluster sized to the
machine by default (processes with one thread each: GTSAM's Python factors hold the GIL), or any running
scheduler by address (`--scheduler tcp://host:8786`, started with `dask scheduler` and `dask worker
tcp://host:8786` on the machines, which need only `pip install gtsam-dvl[distributed]`)."""

from __future__ import annotations

import importlib.util
import logging
import os
import sys
from collections.abc import Iterator, Mapping
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from typing import Any, TypeVar

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn

K = TypeVar("K")

INSTALL_HINT = "Dask is not installed: pip install 'gtsam-dvl[distributed]' (make test and make demo install it)"
# how long to try to reach a --scheduler before giving up (--scheduler-timeout)
SCHEDULER_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class DaskEngine:
    """Where the tasks of a campaign, a fleet or a calibration run (--scheduler, --workers, --scheduler-timeout):
    a running scheduler at `scheduler` (given up after timeout_s), else a LocalCluster of `workers` processes
    here (None: the machine's cores)."""

    scheduler: str | None = None
    workers: int | None = None
    timeout_s: float = SCHEDULER_TIMEOUT_S

    def client(self) -> AbstractContextManager[Any]:
        """dask_client on this engine: the Client, closed on exit with the LocalCluster it started."""
        return dask_client(self.scheduler, self.workers, self.timeout_s)


LOCAL_CLUSTER = DaskEngine()  # the default engine: a LocalCluster of the machine's cores


def require_dask() -> None:
    """A one-line GtsamDvlError naming the install command unless dask.distributed imports: called before a
    campaign or a fleet writes anything."""
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise GtsamDvlError(INSTALL_HINT) from None


def open_client(
    scheduler: str | None, workers: int | None, timeout_s: float = SCHEDULER_TIMEOUT_S
) -> Any:
    """A dask.distributed Client: to the scheduler at `scheduler` (given up after timeout_s), else on a
    LocalCluster of `workers` processes (default: the machine's cores) with one thread each. Says on stderr
    where it runs (the LocalCluster's dashboard address when bokeh is installed)."""
    require_dask()
    from dask.distributed import Client, LocalCluster

    if scheduler:
        if not timeout_s > 0:
            raise GtsamDvlError(
                f"--scheduler-timeout must be a positive number of seconds, got {timeout_s}"
            )
        try:
            client = Client(scheduler, timeout=f"{timeout_s}s")
        except (
            OSError,
            ValueError,
            TypeError,
        ) as exc:  # TimeoutError is an OSError; a bad address a ValueError
            raise GtsamDvlError(
                f"{scheduler}: cannot reach the Dask scheduler ({str(exc).splitlines()[0]}); "
                "start it with `dask scheduler`, or leave --scheduler out for a LocalCluster"
            ) from None
        sys.stderr.write(
            f"Dask scheduler {scheduler}: {len(client.scheduler_info().get('workers', {}))} "
            "workers\n"
        )
        return client
    n = workers or os.cpu_count() or 1
    has_bokeh = importlib.util.find_spec("bokeh") is not None  # the dashboard needs it
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0" if has_bokeh else None,
        silence_logs=logging.ERROR,
    )
    client = Client(cluster)
    dashboard = (
        f"dashboard {client.dashboard_link}"
        if has_bokeh and client.dashboard_link
        else "no dashboard (it needs bokeh: pip install 'gtsam-dvl[distributed]')"
    )
    sys.stderr.write(
        f"Dask LocalCluster: {n} worker process{'es' if n != 1 else ''}, {dashboard}\n"
    )
    return client


@contextmanager
def dask_client(
    scheduler: str | None, workers: int | None, timeout_s: float = SCHEDULER_TIMEOUT_S
) -> Iterator[Any]:
    """open_client's client, closed on exit with the LocalCluster it started (a scheduler's cluster stays)."""
    client = open_client(scheduler, workers, timeout_s)
    try:
        yield client
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()


def finished(
    futures: Mapping[Any, K], progress: ProgressFn | None = None
) -> Iterator[tuple[K, Any, BaseException | None]]:
    """Each task of `futures` (future -> its key) as it finishes, whatever the order: its key, its future and
    the exception it raised (None: it ran; its result stays on the cluster until asked for). progress, when
    given, is told the fraction finished after each."""
    from dask.distributed import as_completed

    for k, fut in enumerate(as_completed(list(futures)), start=1):
        yield futures[fut], fut, fut.exception() if fut.status == "error" else None
        if progress is not None:
            progress(k / len(futures))
