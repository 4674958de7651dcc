"""Jobs: long work in worker processes, with progress, results and artifacts kept in the store.

:class:`JobRunner` runs at most ``workers`` jobs at once, each in its own process (started from a
``forkserver``, never in the event loop), so a job can be cancelled by stopping its process. A
job's work is :data:`WORK` [kind]; it calls the same functions as the ``flatbody`` command
(``family``, ``stability-map``, ``record``, ``evaluate``, ``simulate``) and writes its files to
``DATA_DIR/jobs/ID/``.

A worker process dies with the service (:func:`die_with_service`); a job found ``running``
when the service starts is marked failed with :data:`~flatbody_env.service.store.RESTART_REASON`
and is never re-run silently.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from flatbody_env.service.store import JobStore
from flatbody_env.output import atomic_write

Progress = Callable[[float], None]


# ----------------------------------------------------------------------------------------------
# the work of each kind (runs in the worker process)
# ----------------------------------------------------------------------------------------------
def _simulate(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from flatbody_env.service.answers import trajectory

    progress(0.05)
    _, traj = trajectory(p, in_job=True)
    progress(0.9)
    answer = traj.to_dict()
    atomic_write(out / "trajectory.json", json.dumps(answer) + "\n")
    return answer, ["trajectory.json"]


def _record(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from flatbody_env.recording import record_trajectory
    from flatbody_env.service.answers import trajectory

    progress(0.05)
    scene, traj = trajectory(p, in_job=True, with_rotation=True)
    progress(0.5)
    path = record_trajectory(traj, scene.body, out / "recording.rrd", title=p.get("title"), tensor_every=p["tensor_every"])
    return {
        "recording": path.name,
        "samples": int(traj.t.size),
        "scene": scene.name,
        "t_end": float(traj.t[-1]),
        "method": traj.method,
        "model": traj.model,
        "open_with": f"rerun {path.name}",
    }, [path.name]


def _family(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from analysis.stationary import SearchBox

    from flatbody_env.answers import family_answer
    from flatbody_env.service.answers import build_body

    body = build_body(p["body"])
    progress(0.05)
    box = SearchBox(lam=tuple(p["lam_range"]), mu=tuple(p["mu_range"]), n=p["grid"])
    answer = family_answer(body, p["vary"], p["from"], p["to"], s3=p["s3"], p_theta=p["p_theta"], seeds=p["seeds"], box=box,
                           step=p["step"], out=str(out / "family.csv"), plot=str(out / "family.png"))
    answer["csv"], answer["plot"] = "family.csv", "family.png"
    return answer, ["family.png", "family.csv"]


def _stability_map(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from flatbody_env.answers import stability_map_answer
    from flatbody_env.service.answers import build_body

    body = build_body(p["body"])
    progress(0.05)
    answer = stability_map_answer(body, tuple(p["lam_range"]), tuple(p["mu_range"]), p["grid"],
                                  out=str(out / "stability-map.csv"), plot=str(out / "stability-map.png"))
    return answer, ["stability-map.png", "stability-map.csv"]


def _evaluate(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from agents.evaluate import evaluate_all

    progress(0.05)
    report = evaluate_all(None, episodes=p["episodes"], seed=p["seed"], baselines=p["baselines"])  # the shipped agent only
    atomic_write(out / "evaluation.json", json.dumps(report, indent=2) + "\n")
    return report, ["evaluation.json"]


WORK: dict[str, Callable[[Mapping[str, Any], Path, Progress], tuple[Any, list[str]]]] = {
    "simulate": _simulate,
    "record": _record,
    "family": _family,
    "stability-map": _stability_map,
    "evaluate": _evaluate,
}
"""The work of each job kind: ``(params, folder, progress) → (result, artifact names)``."""


def die_with_service(service_pid: int) -> None:
    """End this worker process as soon as the service process ``service_pid`` has ended.

    Worker processes are forked by a forkserver, so they are not the service's children and
    ``PR_SET_PDEATHSIG`` cannot tie them to it; a daemon thread waits on a pidfd of the service
    (Linux ≥ 5.3; elsewhere it polls the pid twice a second) and exits the process. So a killed
    service leaves no job running behind it.
    """

    def watch() -> None:
        try:
            fd = os.pidfd_open(service_pid)
        except (AttributeError, OSError):
            fd = None
        if fd is not None:
            import select

            select.select([fd], [], [])
        else:
            while True:
                try:
                    os.kill(service_pid, 0)
                except ProcessLookupError:
                    break
                except PermissionError:
                    pass
                time.sleep(0.5)
        os._exit(70)

    if service_pid == os.getpid():
        return
    threading.Thread(target=watch, name="flatbody-service-watch", daemon=True).start()


def run_job(data_dir: str, job_id: str, kind: str, params: dict[str, Any], service_pid: int) -> None:
    """The worker process's entry point: do the job and write its outcome to the store."""
    die_with_service(service_pid)
    os.environ.setdefault("MPLBACKEND", "Agg")
    store = JobStore(data_dir)
    pid = os.getpid()
    store.set_pid(job_id, pid)
    folder = store.job_dir(job_id)
    folder.mkdir(parents=True, exist_ok=True)

    def progress(fraction: float) -> None:
        if not store.progress(job_id, pid, fraction):
            os._exit(0)  # deleted or failed meanwhile: stop working

    try:
        result, artifacts = WORK[kind](params, folder, progress)
    except Exception as exc:  # noqa: BLE001 - every failure becomes the job's one-line error
        from flatbody_env.service.answers import error_data

        store.finish(job_id, pid, error=error_data(exc)["detail"])
        return
    store.finish(job_id, pid, result=result, artifacts=artifacts)


# ----------------------------------------------------------------------------------------------
# the service's side
# ----------------------------------------------------------------------------------------------
def process_context():
    """The multiprocessing context of worker processes: a forkserver (no fork of the threaded service)."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["flatbody_env.service.answers", "flatbody_env.service.jobs", "flatbody_env.simulation", "analysis.stability"])
    return ctx


class JobRunner:
    """Start queued jobs in worker processes (at most ``workers`` at once), reap them, cancel them.

    Parameters
    ----------
    store : JobStore
    workers : int
        Jobs run at once (≥ 1).
    poll : float
        Seconds between looks at the queue when nothing wakes the runner.
    """

    def __init__(self, store: JobStore, workers: int, *, poll: float = 0.2) -> None:
        if workers < 1:
            raise ValueError(f"workers: must be an integer >= 1, got {workers}")
        self.store = store
        self.workers = workers
        self.poll = poll
        self._procs: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._ctx = process_context()

    def start(self) -> int:
        """Fail the jobs a previous service left running, then start the dispatcher; how many were failed."""
        failed = self.store.fail_interrupted()
        self._thread = threading.Thread(target=self._loop, name="flatbody-jobs", daemon=True)
        self._thread.start()
        return failed

    def submit(self, kind: str, params: dict[str, Any]) -> str:
        job_id = self.store.create(kind, params)
        self._wake.set()
        return job_id

    def cancel(self, job_id: str) -> bool:
        """Stop a queued or running job (its process is killed); True if it was queued or running."""
        was_active = self.store.fail(job_id, "cancelled by request", only_running=False)
        with self._lock:
            proc = self._procs.pop(job_id, None)
        if proc is not None:
            _stop_process(proc)
        return was_active

    def running(self) -> int:
        with self._lock:
            return len(self._procs)

    def stop(self) -> None:
        """Stop the dispatcher and the running jobs' processes (their jobs are marked failed)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        with self._lock:
            procs, self._procs = dict(self._procs), {}
        for job_id, proc in procs.items():
            _stop_process(proc)
            self.store.fail(job_id, "the service was stopped while this job was running")

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                self._reap()
                self._launch()
            except Exception as exc:  # noqa: BLE001 - the dispatcher must outlive one bad round
                sys.stderr.write(f"flatbody serve: job dispatcher: {type(exc).__name__}: {exc}\n")
            self._wake.wait(self.poll)
            self._wake.clear()

    def _reap(self) -> None:
        with self._lock:
            done = [(jid, p) for jid, p in self._procs.items() if not p.is_alive()]
            for jid, _ in done:
                del self._procs[jid]
        for jid, proc in done:
            proc.join(timeout=1)
            code = proc.exitcode
            # A worker that ended without writing its outcome (killed, out of memory, crashed):
            self.store.fail(jid, f"the worker process ended without an answer (exit code {code})")

    def _launch(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                if len(self._procs) >= self.workers:
                    return
            job = self.store.claim_next()
            if job is None:
                return
            proc = self._ctx.Process(target=run_job, args=(str(self.store.data_dir), job["id"], job["kind"], job["params"], os.getpid()),
                                     name=f"flatbody-job-{job['id'][:8]}", daemon=True)
            proc.start()
            self.store.set_pid(job["id"], proc.pid)
            with self._lock:
                self._procs[job["id"]] = proc


def _stop_process(proc) -> None:
    proc.terminate()
    proc.join(timeout=3)
    if proc.is_alive():
        proc.kill()
        proc.join(timeout=3)


__all__ = ["JobRunner", "WORK", "die_with_service", "process_context", "run_job"]
