"""Run a sweep: plan its tasks, skip those already stored, run the rest on Dask, store each result
as it arrives.

Each finished task is committed to the store (:mod:`flatbody_env.sweep.store`) by this process as
soon as its future completes, so a sweep killed at any moment keeps every finished row; started
again with ``resume=True`` it runs only the missing keys (no duplicate: the store upserts by key).
A task that raises is stored as an error record and the sweep goes on; a resumed sweep retries it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flatbody_env.sweep.store import ResultStore, StoredResult
from flatbody_env.sweep.tasks import Outcome, Task, execute, extends, plan


@dataclass(frozen=True, kw_only=True)
class SweepReport:
    """The state of a sweep after a run.

    Attributes
    ----------
    spec : dict
        The sweep's specification.
    total : int
        Tasks in the sweep.
    ran : int
        Tasks run by this call (the others were stored already).
    results : tuple of StoredResult
        Every stored outcome, sorted by key.
    """

    spec: dict[str, Any]
    total: int
    ran: int
    results: tuple[StoredResult, ...]

    @property
    def failed(self) -> tuple[StoredResult, ...]:
        return tuple(r for r in self.results if r.status == "error")

    @property
    def missing(self) -> int:
        return self.total - len(self.results)


def _store(store: ResultStore, out: Outcome) -> None:
    store.put(out.key, payload=out.payload, error=out.error, seconds=out.seconds, worker=out.worker)


def run_tasks(
    tasks: list[Task],
    store: ResultStore,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    desc: str = "sweep",
) -> int:
    """Run ``tasks`` (already filtered) and store each outcome as it arrives; returns how many ran.

    ``workers=0`` runs them one after another in this process, without Dask (the reference path);
    otherwise an embedded or remote Dask cluster (:func:`flatbody_env.sweep.cluster.dask_client`).
    """
    from flatbody_env.progress import progress_bar

    if not tasks:
        return 0
    bar = progress_bar(total=len(tasks), desc=desc, unit="task", enabled=progress)
    try:
        if workers == 0 and scheduler is None:
            for task in tasks:
                _store(store, execute(task))
                bar.update(1)
            return len(tasks)
        from distributed import as_completed

        from flatbody_env.sweep.cluster import dask_client

        with dask_client(workers=workers, scheduler=scheduler) as client:
            futures = {  # run in the order of the list (Dask's priority: higher first), whatever the keys
                client.submit(
                    execute, t, key=f"flatbody-sweep-{t.kind}-{t.key}-{id(store)}", pure=False, priority=len(tasks) - i
                ): t
                for i, t in enumerate(tasks)
            }
            try:
                for fut in as_completed(futures):
                    task = futures[fut]
                    try:
                        out = fut.result()
                    except Exception as exc:  # a worker died under the task (KilledWorker) or the cluster failed
                        out = Outcome(
                            key=task.key,
                            payload=None,
                            error=f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}",
                            seconds=0.0,
                            worker="",
                        )
                    _store(store, out)
                    bar.set_postfix_str(task.key, refresh=False)
                    bar.update(1)
            finally:
                for fut in futures:
                    fut.cancel()
        return len(tasks)
    finally:
        bar.close()


def run_sweep(
    spec: dict[str, Any],
    out: str | Path,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    resume: bool = False,
    progress: bool = True,
) -> SweepReport:
    """Run the sweep ``spec`` with results under ``out`` (``out/results.sqlite``).

    Parameters
    ----------
    spec : dict
        The sweep's specification (see :func:`flatbody_env.sweep.tasks.plan`).
    out : str or Path
        Output folder.
    workers : int
        Embedded cluster size (0: in this process, no Dask).
    scheduler : str, optional
        A running Dask scheduler's address (instead of the embedded cluster).
    resume : bool
        Continue the sweep stored in ``out`` (same ``spec``, or one that :func:`~.tasks.extends` it): run only the
        keys without a result.

    Raises
    ------
    ValueError
        ``out`` holds another sweep, or one without ``resume``; ``workers`` < 0.
    """
    from flatbody_env.physics import validation

    validation.integer("workers", workers, low=0)
    tasks = plan(spec, out)
    with ResultStore(out) as store:
        store.begin(spec, resume=resume, extends=extends)
        done = store.done_keys()
        todo = [t for t in tasks if t.key not in done]
        ran = run_tasks(
            todo, store, workers=workers, scheduler=scheduler, progress=progress, desc=f"sweep {spec['kind']}"
        )
        keys = {t.key for t in tasks}
        results = tuple(r for r in store.results() if r.key in keys)
    return SweepReport(spec=spec, total=len(tasks), ran=ran, results=results)


__all__ = ["SweepReport", "run_sweep", "run_tasks"]
