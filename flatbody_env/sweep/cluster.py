"""Where a sweep's tasks run: an embedded Dask cluster (the default) or a real one.

* ``workers=N`` (no scheduler): a ``distributed.LocalCluster`` started for the sweep and closed
  after it — one worker in this process (threads, no pickling, fastest start) for N = 1, N worker
  *processes* on this machine otherwise. Every worker has one thread: tasks that train with torch
  or seed global generators never share a process with another running task.
* ``scheduler="tcp://HOST:8786"``: a cluster started elsewhere (``dask scheduler`` and
  ``dask worker tcp://HOST:8786 --nthreads 1`` on each machine, dask-jobqueue on Slurm, Dask on
  Kubernetes). The workers must be able to import this package (same version) and, for sweeps
  that write files (families, seeds models), see the output folder at the same path.
"""

from __future__ import annotations

import logging
import re
from contextlib import contextmanager
from typing import Iterator

_ADDRESS = re.compile(r"^(tcp|tls|inproc|ws|wss)://[^\s/]+(:\d+)?$")


def check_address(address: str) -> str:
    """``address`` if it looks like a Dask scheduler address; ``ValueError`` naming ``scheduler`` otherwise."""
    if not isinstance(address, str) or not _ADDRESS.match(address):
        raise ValueError(f"scheduler: expected an address like tcp://HOST:8786, got {address!r}")
    return address


@contextmanager
def dask_client(*, workers: int = 1, scheduler: str | None = None, timeout_s: float = 30.0) -> Iterator["object"]:
    """A ``distributed.Client`` for the sweep (closing what it started on exit).

    Parameters
    ----------
    workers : int
        Worker count of the embedded cluster (≥ 1; ignored with ``scheduler``).
    scheduler : str, optional
        Address of a running scheduler.
    timeout_s : float
        How long to wait for the scheduler.

    Raises
    ------
    ValueError
        ``workers`` < 1, or the scheduler cannot be reached (one line).
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        check_address(scheduler)
        try:
            client = Client(scheduler, timeout=timeout_s)
        except (OSError, TimeoutError) as exc:
            raise ValueError(f"scheduler: cannot reach {scheduler} ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})") from None
        try:
            yield client
        finally:
            client.close()
        return
    if not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: must be an integer >= 1, got {workers!r}")
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=workers > 1, dashboard_address=None,
                           silence_logs=logging.CRITICAL)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


__all__ = ["check_address", "dask_client"]
