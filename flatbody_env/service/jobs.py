"""Jobs: long work in worker processes, with progress, results and artifacts kept in the store.

:class:`JobRunner` runs at most ``workers`` jobs at once, each in its own process (started from a
``forkserver``, never in the event loop), so a job can be cancelled by stopping its process. A
job's work is :data:`WORK` [kind]; it calls the same functions as the ``flatbody`` command
(``family``, ``stability-map``, ``record``, ``evaluate``, ``simulate``) and writes its files to
``DATA_DIR/jobs/ID/``.

Progress is the work's own: a job's process turns the command's progress bars
(:func:`flatbody_env.progress.progress_bar`: the stability map's rows, the family's seeds, the
evaluation's episodes) into the job's ``progress`` and ``stage`` (:func:`reporting_bars`), and an
integration reports the time it has reached (:func:`reporting_integration`: a scipy method through its
right-hand side, a compiled method through the time its kernel has written, read while the kernel runs);
each job kind splits 0 … 1 over its steps (:class:`Reporter`), the files it writes included, so that every
job rises through several values before it is done. Progress never decreases.

Each file a job writes is offered for download under a name that says what it holds (:func:`download_name`:
``flatbody-record-default-t5-1a2b3c4d.rrd``), not under the same ``recording.rrd`` for every job.

A worker process dies with the service (:func:`die_with_service`); a job found ``running``
when the service starts is marked failed with :data:`~flatbody_env.service.store.RESTART_REASON`
and is never re-run silently.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from flatbody_env.service.store import JobStore, MissingDatabase
from flatbody_env.output import OutputError, atomic_path, atomic_write

Progress = Callable[..., None]
"""``progress(fraction, stage=None)``: record the job's progress (0 … 1) and what it is doing."""

REPORT_EVERY_S = 0.2
"""Least seconds between two progress writes of one job (the first and the last of a step always go)."""


class Reporter:
    """The job's progress over its steps: step ``k`` of a job covers ``[lo, hi]`` of 0 … 1.

    ``step(lo, hi, stage)`` starts a step; ``part(fraction, stage)`` reports how far into the current
    step the work is (0 … 1). Writes are at most one per :data:`REPORT_EVERY_S` seconds, and the
    reported value never decreases.
    """

    def __init__(self, progress: Progress, *, every: float | None = None) -> None:
        self._progress = progress
        self.every = REPORT_EVERY_S if every is None else every
        self.lo, self.hi = 0.0, 0.0
        self.done = 0.0
        self._last = -1e9
        self.stage: str | None = None

    def step(self, lo: float, hi: float, stage: str | None = None) -> None:
        self.lo, self.hi = float(lo), float(hi)
        self._report(self.lo, stage, force=True)

    def part(self, fraction: float, stage: str | None = None, *, force: bool = False) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        self._report(self.lo + (self.hi - self.lo) * fraction, stage, force=force)

    def _report(self, value: float, stage: str | None, *, force: bool = False) -> None:
        now = time.monotonic()
        if stage is not None:
            self.stage = stage
        if not force and now - self._last < self.every:
            return
        self.done = max(self.done, value)
        self._last = now
        self._progress(self.done, self.stage)


def _bar_class(reporter: Reporter, bars: int):
    """A silent :class:`~flatbody_env.progress.LineProgress` that reports to ``reporter``; the ``bars``
    bars a job's work opens one after the other share its current step evenly."""
    from flatbody_env.progress import LineProgress

    opened = [0]

    class JobBar(LineProgress):
        def __init__(self, iterable=None, *, total=None, desc="", unit="it", initial=0, **_ignored) -> None:
            super().__init__(iterable, total=total, desc=desc, unit=unit, initial=initial, enabled=False)
            self.index = min(opened[0], bars - 1)
            opened[0] += 1
            self._tell(force=True)

        def update(self, n: int = 1) -> None:
            super().update(n)
            self._tell()

        def close(self) -> None:
            if not self._closed and self.index == bars - 1 and (not self.total or self.n >= self.total):
                reporter.part(1.0, None, force=True)
            super().close()

        def _tell(self, force: bool = False) -> None:
            share = (self.n / self.total) if self.total else 0.0
            units = self.unit if self.unit.endswith("s") else self.unit + "s"
            what = f"{self.desc}: " if self.desc else ""
            stage = f"{what}{self.n} of {self.total} {units}" if self.total else f"{what}{self.n} {units}"
            reporter.part((self.index + min(share, 1.0)) / bars, stage, force=force)

    return JobBar


@contextmanager
def reporting_bars(reporter: Reporter, *, bars: int = 1) -> Iterator[None]:
    """While inside, the command's progress bars (:func:`flatbody_env.progress.progress_bar`) in this
    worker process report to ``reporter`` instead of printing (one job per process, so this is the job's)."""
    import flatbody_env.progress as progress_module

    bar = _bar_class(reporter, max(1, bars))
    saved = progress_module.progress_bar

    def progress_bar(iterable=None, **kwargs):
        return bar(iterable, **kwargs)

    progress_module.progress_bar = progress_bar
    try:
        yield
    finally:
        progress_module.progress_bar = saved


@contextmanager
def reporting_integration(reporter: Reporter, t_end: float) -> Iterator[None]:
    """While inside, an integration in this worker process reports ``t / t_end``, the time it has reached: a
    scipy method (``scipy.integrate.solve_ivp``) from its right-hand side's calls, a compiled method (the
    default ``auto``: DOP853-numba, RATTLE) from the time its kernel has written so far, read while the kernel
    runs (:func:`flatbody_env.integrators.compiled_methods.watching_kernels`)."""
    import scipy.integrate

    from flatbody_env.integrators.compiled_methods import watching_kernels

    saved = scipy.integrate.solve_ivp

    def solve_ivp(fun, t_span, y0, *args, **kwargs):
        t0, t1 = float(t_span[0]), float(t_span[-1])
        width = (t1 - t0) or 1.0
        calls = [0]

        def watched(t, y, *more):
            calls[0] += 1
            if calls[0] % 32 == 0:
                reporter.part((float(t) - t0) / width, f"integrating: t = {float(t):.4g} of {t_end:g}")
            return fun(t, y, *more)

        return saved(watched, t_span, y0, *args, **kwargs)

    def kernel_reached(t: float, t0: float, t1: float) -> None:
        reporter.part((t - t0) / ((t1 - t0) or 1.0), f"integrating: t = {t:.4g} of {t_end:g}")

    scipy.integrate.solve_ivp = solve_ivp
    try:
        with watching_kernels(kernel_reached):
            yield
    finally:
        scipy.integrate.solve_ivp = saved


def download_name(kind: str, params: Mapping[str, Any], job_id: str, artifact: str) -> str:
    """The name a job's file ``artifact`` is offered under: what it holds and the job, e.g.
    ``flatbody-record-default-t5-1a2b3c4d.rrd``, ``flatbody-family-J-1e-06-to-1e+06-1a2b3c4d.png`` (letters, digits
    and ``.+-_`` only)."""
    import re

    def num(x: Any) -> str:
        return f"{float(x):g}" if isinstance(x, (int, float)) else "default"

    if kind in ("simulate", "record"):
        scene = params.get("scene")
        what = scene if isinstance(scene, str) else "custom"
        what += f"-t{num(params['t_end'])}" if params.get("t_end") else ""
    elif kind == "family":
        what = f"{params.get('vary', 's3')}-{num(params.get('from'))}-to-{num(params.get('to'))}"
    elif kind == "stability-map":
        what = f"{params.get('grid', '')}x{params.get('grid', '')}"
    else:
        what = "agent"
    stem, dot, suffix = artifact.rpartition(".")
    part = "" if stem in ("recording", "trajectory", "family", "stability-map", "evaluation") else f"-{stem}"
    name = f"flatbody-{kind}-{what}{part}-{job_id[:8]}{dot}{suffix}"
    return re.sub(r"[^A-Za-z0-9.+_-]", "_", name)[:120]


# ----------------------------------------------------------------------------------------------
# the work of each kind (runs in the worker process)
# ----------------------------------------------------------------------------------------------
def _integrate(p: Mapping[str, Any], report: Reporter, lo: float, hi: float, **options):
    """The job's trajectory (as ``flatbody simulate``), its progress reported over ``[lo, hi]``."""
    from flatbody_env.service.answers import build_scene, trajectory

    t_end = p.get("t_end") or build_scene(p["scene"]).t_end
    report.step(lo, hi, f"integrating to t = {t_end:g}")
    with reporting_integration(report, t_end):
        scene, traj = trajectory(p, in_job=True, **options)
    report.part(1.0, f"integrated to t = {t_end:g} ({traj.method})", force=True)
    return scene, traj


def _job_id(out: Path) -> str:
    """The job's id: the name of its folder (``DATA_DIR/jobs/ID``)."""
    return out.name


def _write_trajectory(traj, out: Path, report: Reporter, lo: float, hi: float) -> dict[str, Any]:
    """``trajectory.json`` (``flatbody simulate --out``), reported over ``[lo, hi]``: the JSON form, then the file."""
    report.step(lo, lo + 0.5 * (hi - lo), f"preparing trajectory.json ({traj.t.size} samples)")
    answer = traj.to_dict()
    text = json.dumps(answer) + "\n"
    report.step(lo + 0.5 * (hi - lo), hi, f"writing trajectory.json ({len(text) / 1e6:.1f} MB)")
    atomic_write(out / "trajectory.json", text)
    return answer


def _simulate(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    report = Reporter(progress)
    _, traj = _integrate(p, report, 0.02, 0.8)
    answer = _write_trajectory(traj, out, report, 0.8, 0.98)
    return answer, ["trajectory.json"]


PREVIEW_FRAMES = 4
"""Frames of a recording job's preview (``preview.png``): the body at evenly spaced times, first and last included."""


def write_preview(traj, path: Path) -> Path:
    """A recording's preview: :data:`PREVIEW_FRAMES` frames of the plate seen from +z (the ``rgb_array`` frame,
    :func:`flatbody_env.env.rendering.render_frame`) at evenly spaced times of ``traj`` side by side, written to
    ``path`` (PNG)."""
    import numpy as np
    from PIL import Image

    from flatbody_env.env.rendering import FRAME_GAP, SIZE, render_frame

    n = traj.t.size
    picks = np.unique(np.linspace(0, n - 1, min(PREVIEW_FRAMES, n)).round().astype(int))
    lam, mu = traj.state["lambda"], traj.state["mu"]
    from flatbody_env.env.rendering import view_half_width

    half = max(view_half_width(float(lam[k]), float(mu[k])) for k in range(n))  # one scale for every frame
    strip = np.full((SIZE, len(picks) * SIZE + (len(picks) - 1) * FRAME_GAP, 3), 255, dtype=np.uint8)
    for j, k in enumerate(picks):
        strip[:, j * (SIZE + FRAME_GAP) : j * (SIZE + FRAME_GAP) + SIZE] = render_frame(
            traj.y[:, k], traj.rotation[k], {}, float(traj.t[k]), half_width=half
        )
    with atomic_path(path) as tmp:
        Image.fromarray(strip).save(tmp, format="PNG", optimize=True)
    return path


def _record(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from flatbody_env.recording import record_trajectory

    report = Reporter(progress)
    scene, traj = _integrate(p, report, 0.02, 0.3, with_rotation=True)
    report.step(0.3, 0.4, "loading the rerun SDK")
    import rerun  # noqa: F401  (its import is the first second of a recording: reported on its own)

    report.step(0.4, 0.75, f"writing recording.rrd ({traj.t.size} samples)")
    target = out / "recording.rrd"
    # a failed or killed job leaves no half-written recording.rrd (the runner removes the temporary file of a killed one);
    # a write that fails (disk full, file-size limit) is an OutputError here, never a hang (flatbody_env.recording.sink)
    try:
        with reporting_bars(report), atomic_path(target) as tmp:
            record_trajectory(traj, scene.body, tmp, title=p.get("title"), tensor_every=p["tensor_every"])
    except OutputError as exc:  # the job's error names its file, not the service's folders
        raise OutputError(str(exc).replace(repr(str(target)), repr(target.name))) from None
    report.step(0.75, 0.85, "drawing preview.png (the body at four times)")
    write_preview(traj, out / "preview.png")
    _write_trajectory(traj, out, report, 0.85, 0.98)
    download = download_name("record", p, _job_id(out), target.name)
    return {
        "recording": target.name,
        "download": download,
        "preview": "preview.png",
        "samples": int(traj.t.size),
        "scene": scene.name,
        "t_end": float(traj.t[-1]),
        "method": traj.method,
        "model": traj.model,
        "open_with": f"rerun {download}",
    }, [target.name, "preview.png", "trajectory.json"]


def _family(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from analysis.stationary import SearchBox

    from flatbody_env.answers import family_answer
    from flatbody_env.service.answers import build_body

    report = Reporter(progress)
    body = build_body(p["body"])
    report.step(0.02, 0.75, f"following the family over {p['vary']}")
    box = SearchBox(lam=tuple(p["lam_range"]), mu=tuple(p["mu_range"]), n=p["grid"])
    stages = {"csv": (0.75, 0.8, "writing family.csv"), "plot": (0.8, 0.98, "drawing family.png (matplotlib)")}
    with reporting_bars(report):
        answer = family_answer(
            body,
            p["vary"],
            p["from"],
            p["to"],
            s3=p["s3"],
            p_theta=p["p_theta"],
            seeds=p["seeds"],
            box=box,
            step=p["step"],
            out=str(out / "family.csv"),
            plot=str(out / "family.png"),
            progress=True,
            names=("from", "to"),
            on_stage=lambda stage: report.step(*stages[stage]),
        )
    answer["csv"], answer["plot"] = "family.csv", "family.png"
    return answer, ["family.png", "family.csv"]


def _stability_map(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from flatbody_env.answers import stability_map_answer
    from flatbody_env.service.answers import build_body

    report = Reporter(progress)
    body = build_body(p["body"])
    report.step(0.02, 0.8, f"stability map: {p['grid']} × {p['grid']} shapes")
    stages = {
        "csv": (0.8, 0.84, "writing stability-map.csv"),
        "plot": (0.84, 0.98, "drawing stability-map.png (matplotlib)"),
    }
    with reporting_bars(report):
        answer = stability_map_answer(
            body,
            tuple(p["lam_range"]),
            tuple(p["mu_range"]),
            p["grid"],
            out=str(out / "stability-map.csv"),
            plot=str(out / "stability-map.png"),
            progress=True,
            on_stage=lambda stage: report.step(*stages[stage]),
        )
    return answer, ["stability-map.png", "stability-map.csv"]


def _evaluate(p: Mapping[str, Any], out: Path, progress: Progress) -> tuple[Any, list[str]]:
    from agents.evaluate import baselines_for, evaluate_all, shipped_model_dir
    from agents.numpy_policy import read_run_config

    report = Reporter(progress)
    report.step(0.02, 0.95, "evaluating the shipped agent")
    env_id = read_run_config(shipped_model_dir())["env_id"]  # its task: the baselines (and bars) of that task
    bars = 1 + (len(baselines_for(env_id)) if p["baselines"] else 0)
    with reporting_bars(report, bars=bars):
        report_json = evaluate_all(
            None, episodes=p["episodes"], seed=p["seed"], baselines=p["baselines"], progress=True
        )  # the shipped agent only
    report.step(0.95, 0.98, "writing evaluation.json")
    atomic_write(out / "evaluation.json", json.dumps(report_json, indent=2) + "\n")
    return report_json, ["evaluation.json"]


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

    The worker also ignores SIGINT: a Ctrl-C at the terminal reaches the whole process group, and
    it is the service's to handle (it stops its workers and jobs itself), not a traceback per worker.
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
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=watch, name="flatbody-service-watch", daemon=True).start()


def run_job(data_dir: str, job_id: str, kind: str, params: dict[str, Any], service_pid: int) -> None:
    """The worker process's entry point: do the job and write its outcome to the store."""
    die_with_service(service_pid)
    os.environ.setdefault("MPLBACKEND", "Agg")
    store = JobStore(data_dir, create=False)
    pid = os.getpid()
    try:
        store.set_pid(job_id, pid)
    except MissingDatabase:  # the database went away under the service: nowhere to report, nothing to do
        return
    folder = store.job_dir(job_id)
    folder.mkdir(parents=True, exist_ok=True)

    def progress(fraction: float, stage: str | None = None) -> None:
        if not store.progress(job_id, pid, fraction, stage):
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
    ctx.set_forkserver_preload(
        ["flatbody_env.service.answers", "flatbody_env.service.jobs", "flatbody_env.simulation", "analysis.stability"]
    )
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
        from flatbody_env.physics import validation

        self.store = store
        self.workers = validation.workers("workers", workers)
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

    def submit(self, kind: str, params: dict[str, Any], **quota: Any) -> str:
        """Queue a job (``quota``: the :meth:`JobStore.create` limits and client); its id."""
        job_id = self.store.create(kind, params, **quota)
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
            # A worker that ended without writing its outcome (killed, out of memory, crashed): the job fails
            # with one line, and the temporary files of its unfinished writes are removed.
            if self.store.fail(jid, exit_reason(proc.exitcode)):
                remove_partial_files(self.store.job_dir(jid))

    def _launch(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                if len(self._procs) >= self.workers:
                    return
            job = self.store.claim_next()
            if job is None:
                return
            proc = self._ctx.Process(
                target=run_job,
                args=(str(self.store.data_dir), job["id"], job["kind"], job["params"], os.getpid()),
                name=f"flatbody-job-{job['id'][:8]}",
                daemon=True,
            )
            proc.start()
            self.store.set_pid(job["id"], proc.pid)
            with self._lock:
                self._procs[job["id"]] = proc


def exit_reason(code: int | None) -> str:
    """The one-line error of a job whose worker process ended without writing its outcome (exit code ``code``)."""
    if code is not None and code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        if name == "SIGXFSZ":
            return "the job's file went over the service's file-size limit (RLIMIT_FSIZE); the worker process was stopped by SIGXFSZ"
        if name == "SIGKILL":
            return "the worker process was killed (SIGKILL: out of memory?) before it answered"
        return f"the worker process ended without an answer (killed by {name})"
    return f"the worker process ended without an answer (exit code {code})"


def remove_partial_files(folder: Path) -> None:
    """Remove the temporary files (``.NAME.XXXX.tmp.SUFFIX``, :func:`flatbody_env.output.atomic_path`) a killed
    worker left in a job's folder; finished files are never touched."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        if entry.name.startswith(".") and ".tmp" in entry.name and entry.is_file():
            with suppress(OSError):
                entry.unlink()


def _stop_process(proc) -> None:
    proc.terminate()
    proc.join(timeout=3)
    if proc.is_alive():
        proc.kill()
        proc.join(timeout=3)


__all__ = [
    "JobRunner",
    "REPORT_EVERY_S",
    "Reporter",
    "WORK",
    "die_with_service",
    "download_name",
    "exit_reason",
    "process_context",
    "remove_partial_files",
    "reporting_bars",
    "reporting_integration",
    "run_job",
    "write_preview",
]
