"""Body-steps per second of the batched dynamics against N, on every backend this machine has.

What is timed: one environment step of N bodies (dynamics only: no observation, reward or reset),
dt = 0.05, RK4 with h = dt/4 and DOP853 at rtol = atol = 1e-11 (the env's default), no controls,
bodies of the default shape on a regular orbit with perturbed momenta. The figure is N · steps / seconds, the best of
``repeats`` timed blocks of ``steps`` steps, after one untimed step (compilation).

Backends:

* ``cpu-serial`` — ``env_stepper(NAME).batch``: the env's compiled loop over bodies, one thread;
* ``cpu-parallel`` — :func:`~.batch_solve.batch_env_step`: the same kernels, ``numba.prange`` over
  chunks of bodies (all cores);
* ``cuda`` — :func:`~.cuda.env_step`: the same source compiled for the GPU, one thread per body,
  one launch per step, state kept on the device (present only where a CUDA GPU is; numba's
  simulator is never timed).

Rows: ``{"what", "backend", "method", "n", "steps_per_s", "device_name"}``.

The whole env step (controls, observation, rewards, termination, autoresets) is timed on the same backends by
:mod:`flatbody_env.env.device_bench` (``flatbody bench gpu`` adds its rows to these).
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from flatbody_env.integrators import batch_solve as bs
from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
from flatbody_env.output import save_figure

WHAT = "env step, dynamics only"
DT = 0.05
RK4_STEP = DT / 4
DOP853_TOL = 1e-11
DEFAULT_SIZES = (256, 1024, 4096, 16384, 65536)
DEFAULT_METHODS = ("RK4", "DOP853-numba")


def cpu_name() -> str:
    """The CPU's model name and core count."""
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    name = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{name} ({os.cpu_count()} cores)"


BASE_STATE = np.array([0.05, 0.0, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.0])
"""A regular orbit of :func:`~flatbody_env.physics.body.default_body` (the state ``warm_up`` uses)."""


def _bodies(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    Y0 = np.tile(BASE_STATE, (n, 1))
    Y0[:, :7] += 0.05 * rng.normal(size=(n, 7))
    return np.ascontiguousarray(Y0.T)


def backends() -> tuple[list[str], list[str]]:
    """(backends to time here, notes on the ones left out)."""
    from flatbody_env.integrators import cuda

    names, notes = ["cpu-serial", "cpu-parallel"], []
    if cuda.simulated():
        notes.append("cuda: numba's CUDA simulator is on (NUMBA_ENABLE_CUDASIM); it is never timed")
    elif cuda.is_available():
        names.append("cuda")
    else:
        notes.append(cuda._probe()[1])
    return names, notes


def _time_cpu(step, Y, steps: int, repeats: int) -> float:
    A, B = Y.copy(), np.empty_like(Y)
    step(A, B)  # compile / warm
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(steps):
            step(A, B)
            A, B = B, A
        best = min(best, time.perf_counter() - t0)
    return best


def measure(backend: str, method: str, n: int, *, steps: int, repeats: int) -> float:
    """Body-steps per second of ``method`` on ``backend`` for ``n`` bodies."""
    from flatbody_env.physics.body import default_body

    P = kernel_params(default_body())
    Y = _bodies(n)
    U = np.zeros((4, n))
    kind, coeffs = bs.KIND[method]
    h = RK4_STEP if kind != bs.DOP853_KIND else 0.0
    status, nfev = np.zeros(n, np.int64), np.zeros(n, np.int64)
    if backend == "cpu-serial":
        batch = env_stepper(method).batch

        def step(A, B):
            batch(A, U, P, DT, h, DOP853_TOL, DOP853_TOL, np.inf, B, status)

        seconds = _time_cpu(step, Y, steps, repeats)
    elif backend == "cpu-parallel":
        def step(A, B):
            bs.batch_env_step(kind, coeffs, A, U, P, DT, h, DOP853_TOL, DOP853_TOL, np.inf, B, status, nfev)

        seconds = _time_cpu(step, Y, steps, repeats)
    elif backend == "cuda":
        from flatbody_env.integrators import cuda

        dev = cuda.require()
        dA, dB = dev.to_device(Y), dev.device_array_like(Y)
        dU, dP = dev.to_device(U), dev.to_device(P)
        dS, dN = dev.device_array(n, np.int64), dev.device_array(n, np.int64)

        def launch(A, B):
            cuda.env_step(method, A, dU, dP, DT, h=h, rtol=DOP853_TOL, atol=DOP853_TOL, OUT=B, STATUS=dS, NFEV=dN)

        launch(dA, dB)
        dev.synchronize()
        seconds = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            for _ in range(steps):
                launch(dA, dB)
                dA, dB = dB, dA
            dev.synchronize()
            seconds = min(seconds, time.perf_counter() - t0)
    else:
        raise ValueError(f"backend: unknown {backend!r} (allowed: cpu-serial, cpu-parallel, cuda)")
    return n * steps / seconds


def run(*, sizes=DEFAULT_SIZES, methods=DEFAULT_METHODS, steps: int = 10, repeats: int = 3, only=None, progress=None) -> dict:
    """Every backend here (or those of ``only`` among them) × ``methods`` × ``sizes``: ``{"rows", "settings", "left_out"}``."""
    names, notes = backends()
    if only is not None:
        notes += [f"{b}: not asked for" for b in names if b not in only]
        names = [b for b in names if b in only]
        if not names:
            raise ValueError(f"backends: none of {', '.join(only)} is here ({'; '.join(notes)})")
    device_names = {"cpu-serial": cpu_name(), "cpu-parallel": cpu_name()}
    if "cuda" in names:
        from flatbody_env.integrators import cuda

        device_names["cuda"] = cuda.device_name()
    rows = []
    for backend in names:
        for method in methods:
            for n in sizes:
                rate = measure(backend, method, int(n), steps=steps, repeats=repeats)
                row = {"what": WHAT, "backend": backend, "method": method, "n": int(n), "steps_per_s": rate,
                       "device_name": device_names[backend]}
                rows.append(row)
                if progress is not None:
                    progress(row)
    settings = {"dt": DT, "rk4_step": RK4_STEP, "dop853_rtol": DOP853_TOL, "dop853_atol": DOP853_TOL, "steps": steps, "repeats": repeats,
                "threads": _threads()}
    return {"rows": rows, "settings": settings, "left_out": notes}


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


def plot(result: dict, path: str | Path) -> None:
    """Body-steps/s against N, one line per backend and method (log–log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4.8))
    keys = sorted({(r["what"], r["backend"], r["method"]) for r in result["rows"]})
    for what, backend, method in keys:
        rows = sorted((r for r in result["rows"] if r["what"] == what and r["backend"] == backend and r["method"] == method), key=lambda r: r["n"])
        whole = what != WHAT
        ax.plot([r["n"] for r in rows], [r["steps_per_s"] for r in rows], marker="s" if whole else "o",
                linestyle=":" if whole else ("-" if method == "RK4" else "--"),
                label=f"{'whole env, ' if whole else ''}{backend}, {method} ({rows[0]['device_name']})")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("bodies N")
    ax.set_ylabel("body-steps / s")
    ax.set_title(f"one env step of N bodies: dynamics alone (lines) and the whole env step (dotted), dt = {DT:g}\n"
                 f"RK4 h = dt/4, DOP853 tol {DOP853_TOL:g}; best of {result['settings']['repeats']} blocks of "
                 f"{result['settings']['steps']} steps", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


__all__ = ["DEFAULT_METHODS", "DEFAULT_SIZES", "WHAT", "backends", "cpu_name", "measure", "plot", "run"]
