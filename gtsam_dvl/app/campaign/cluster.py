"""The Dask client of a campaign or a fleet: dask.distributed, not a home-made pool. A LocalCluster sized to the
machine by default (processes with one thread each: GTSAM's Python factors hold the GIL), or any running
scheduler by address (`--scheduler tcp://host:8786`, started with `dask scheduler` and `dask worker
tcp://host:8786` on the machines, which need only `pip install gtsam-dvl[distributed]`)."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError

INSTALL_HINT = "Dask is not installed: pip install 'gtsam-dvl[distributed]' (make test and make demo install it)"


def open_client(scheduler: str | None, workers: int | None) -> Any:
    """A dask.distributed Client: to the scheduler at `scheduler`, else on a LocalCluster of `workers` processes
    (default: the machine's cores) with one thread each."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise GtsamDvlError(INSTALL_HINT) from None
    if scheduler:
        try:
            return Client(scheduler, timeout="20s")
        except OSError as exc:
            raise GtsamDvlError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster)


@contextmanager
def dask_client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """open_client's client, closed on exit with the LocalCluster it started (a scheduler's cluster stays)."""
    client = open_client(scheduler, workers)
    try:
        yield client
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()
