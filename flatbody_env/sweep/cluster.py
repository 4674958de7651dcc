"""Where a sweep's tasks run: an embedded Dask cluster (the default) or a real one.

* ``workers=N`` (no scheduler): a ``distributed.LocalCluster`` started for the sweep and closed
  after it — one worker in this process (threads, no pickling, fastest start) for N = 1, N worker
  *processes* on this machine otherwise. Every worker has one thread: tasks that train with torch
  or seed global generators never share a process with another running task.
* Ctrl-C is the sweep's, not the workers': the terminal sends SIGINT to the whole process group,
  so the embedded cluster's worker processes are started with SIGINT blocked
  (:func:`workers_leave_sigint`) and never print a traceback of their own; the sweep stops them
  when it ends (:func:`dask_client`'s exit).
* ``scheduler="tcp://HOST:8786"``: a cluster started elsewhere (``dask scheduler`` and
  ``dask worker tcp://HOST:8786 --nthreads 1`` on each machine, dask-jobqueue on Slurm, Dask on
  Kubernetes). The workers must be able to import this package (same version) and, for sweeps
  that write files (families, seeds models), see the output folder at the same path.
"""

from __future__ import annotations

import logging
import re
import signal
import threading
from contextlib import contextmanager
from collections.abc import Iterator

_ADDRESS = re.compile(r"^(tcp|tls|inproc|ws|wss)://[^\s/]+(:\d+)?$")


QUIET_SCHEDULER = {"dashboard": False, "dashboard_address": "127.0.0.1:0"}
"""Scheduler options of the embedded clusters: no dashboard, and the scheduler's small HTTP server
(health, metrics) on a free loopback port, not on 8787, which a second sweep (or any Dask cluster)
running on the machine holds: that would print a three-line warning."""


def check_address(address: str) -> str:
    """``address`` if it looks like a Dask scheduler address; ``ValueError`` naming ``scheduler`` otherwise."""
    if not isinstance(address, str) or not _ADDRESS.match(address):
        raise ValueError(f"scheduler: expected an address like tcp://HOST:8786, got {address!r}")
    return address


@contextmanager
def workers_leave_sigint() -> Iterator[None]:
    """Start processes inside this block and they never receive Ctrl-C: it stays this process's.

    SIGINT is blocked in the calling thread for the block. Threads started inside (Dask's event
    loop, its process watchers) inherit the blocked mask, and so do the processes they start (the
    mask survives fork and exec), so a Ctrl-C at the terminal reaches this process alone. One that
    arrives during the block is kept pending and delivered (KeyboardInterrupt) when it ends. Outside
    the main thread, or where ``pthread_sigmask`` is missing, the block changes nothing.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # multiprocessing starts its resource tracker at the first lock, and unblocks SIGINT in the thread
    # that starts it: start it now, so that no thread unblocks what this block blocks
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextmanager
def dask_client(*, workers: int = 1, scheduler: str | None = None, timeout_s: float = 30.0) -> Iterator[object]:
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
            raise ValueError(
                f"scheduler: cannot reach {scheduler} ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})"
            ) from None
        try:
            yield client
        finally:
            client.close()
        return
    from flatbody_env.physics import validation

    validation.integer("workers", workers, low=1)
    cluster = client = None
    try:
        with workers_leave_sigint():  # a Ctrl-C during the start is raised at the end of this block: the finally closes
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=workers > 1,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
                scheduler_kwargs=QUIET_SCHEDULER,
            )
            client = Client(cluster)
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


__all__ = ["QUIET_SCHEDULER", "check_address", "dask_client", "workers_leave_sigint"]
