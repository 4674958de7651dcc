"""``flatbody bench gpu``: body-steps per second against N, on every backend this machine has — of the batched
dynamics alone, then of the whole env step.

Dynamics only (``what`` = :data:`WHAT`): one environment step of N bodies (no observation, reward or reset),
dt = 0.05, RK4 with h = dt/4 and DOP853 at rtol = atol = 1e-11 (the env's default), no controls, bodies of the
default shape on a regular orbit with perturbed momenta, on

* ``cpu-serial`` — ``env_stepper(NAME).batch``: the env's compiled loop over bodies, one thread;
* ``cpu-parallel`` — :func:`~flatbody_env.bench.kernels.batch_env_step_parallel`: the same kernels,
  ``numba.prange`` over chunks of bodies (all cores; the bench's own kernel, :mod:`.kernels`);
* ``cuda`` — :func:`~flatbody_env.integrators.cuda.env_step`: the same source compiled for the GPU, one thread
  per body, one launch per step, state kept on the device.

The whole env step (``what`` = :data:`WHAT_ENV`, ``env`` the id): random actions in [−1, 1], the controls, the
dynamics, the task's observation, reward, termination and autoresets (the transition,
:mod:`flatbody_env.env.transition`), the id's defaults (its DOP853), 400-step episodes started with staggered clocks
so that resets fall in every step, on

* ``cpu-serial`` — :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` (SAME_STEP) ``step``, one thread (the
  CPU env as users run it), ``FlatBody-v1``;
* ``cuda`` — :class:`~flatbody_env.env.core.EnvCore` on CUDA: one launch per step, actions and every array on the
  device, with the per-step read of the two-integer error flag (the kernels ``FlatBodyTorchVectorEnv(device="cuda")``
  launches; its tensor wrapping is not timed), every v1 id.

Each figure is N · steps / seconds, the best of ``repeats`` timed blocks of ``steps`` steps (:func:`.harness.best_of`),
after one untimed step (compilation); a CUDA block ends with a device synchronisation. numba's CUDA simulator is
never timed. Rows: ``{"what", "env", "backend", "method", "n", "steps_per_s", "device_name"}`` (``env`` "" for the
dynamics rows).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flatbody_env.bench.harness import Report, Table, best_of
from flatbody_env.physics import validation
from flatbody_env.provenance import cpu_name

WHAT = "env step, dynamics only"
WHAT_ENV = "env step, whole (controls, dynamics, observation, rewards, termination, autoresets)"
BACKENDS = ("cpu-serial", "cpu-parallel", "cuda")
"""Every backend a row can come from (module docstring); those present here: :func:`backends`."""
ENV_BACKENDS = ("cpu-serial", "cuda")
"""The backends with whole-env rows."""
ROW_KEYS = ("what", "env", "backend", "method", "n", "steps_per_s", "device_name")
"""A row's keys: the CSV's columns."""
DT = 0.05
RK4_STEP = DT / 4
DOP853_TOL = 1e-11
DEFAULT_SIZES = (256, 1024, 4096, 16384, 65536)
DEFAULT_METHODS = ("RK4", "DOP853-numba")

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

    names, notes = [b for b in BACKENDS if b != "cuda"], []
    if cuda.simulated():
        notes.append("cuda: numba's CUDA simulator is on (NUMBA_ENABLE_CUDASIM); it is never timed")
    else:
        try:
            cuda.require()
            names.append("cuda")
        except cuda.CudaUnavailableError as exc:
            notes.append(str(exc))
    return names, notes


def _ping_pong(step, A, B, steps: int, sync=None):
    """After one untimed ``step(A, B)`` (compilation): a block of ``steps`` steps from A to B and back,
    synchronised at its end by ``sync()`` when given."""
    bufs = [A, B]
    step(A, B)
    if sync is not None:
        sync()

    def block() -> None:
        for _ in range(steps):
            step(bufs[0], bufs[1])
            bufs.reverse()
        if sync is not None:
            sync()

    return block


def measure(backend: str, method: str, n: int, *, steps: int, repeats: int) -> float:
    """Body-steps per second of the dynamics alone, ``method`` on ``backend`` for ``n`` bodies."""
    from flatbody_env.integrators import batch_solve as bs
    from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
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

        block = _ping_pong(step, Y.copy(), np.empty_like(Y), steps)
    elif backend == "cpu-parallel":
        from flatbody_env.bench.kernels import batch_env_step_parallel

        def step(A, B):
            batch_env_step_parallel(kind, coeffs, A, U, P, DT, h, DOP853_TOL, DOP853_TOL, np.inf, B, status, nfev)

        block = _ping_pong(step, Y.copy(), np.empty_like(Y), steps)
    elif backend == "cuda":
        from flatbody_env.integrators import cuda

        dev = cuda.require()
        dU, dP = dev.to_device(U), dev.to_device(P)
        dS, dN = dev.device_array(n, np.int64), dev.device_array(n, np.int64)

        def step(A, B):
            cuda.env_step(method, A, dU, dP, DT, h=h, rtol=DOP853_TOL, atol=DOP853_TOL, OUT=B, STATUS=dS, NFEV=dN)

        block = _ping_pong(step, dev.to_device(Y), dev.device_array_like(Y), steps, dev.synchronize)
    else:
        raise ValueError(f"backend: unknown {backend!r} (allowed: {', '.join(BACKENDS)})")
    return n * steps / best_of(block, repeats, warm=False)


def measure_env(backend: str, n: int, *, steps: int, repeats: int, env_id: str = "FlatBody-v1") -> tuple[str, float]:
    """(method, body-steps per second) of the whole env step of ``n`` bodies of ``env_id`` on ``backend`` (module docstring)."""
    from flatbody_env.env.registration import task_spec

    kwargs = dict(task_spec(env_id).kwargs)
    rng = np.random.default_rng(0)
    if backend == "cpu-serial":
        from gymnasium.vector import AutoresetMode

        from flatbody_env.env.vector_env import FlatBodyVectorEnv

        env = FlatBodyVectorEnv(num_envs=n, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs)
        env.reset(seed=0, options={"stagger": True})
        blocks = [
            rng.uniform(-1, 1, (steps + 1, n) + env.single_action_space.shape).astype(np.float32)
            for _ in range(repeats)
        ]
        env.step(blocks[0][0])  # compile / warm
        actions = iter(blocks)

        def block() -> None:
            A = next(actions)
            for k in range(steps):
                env.step(A[k])

        seconds = best_of(block, repeats, warm=False)
        method = env.stepper.method
        env.close()
        return method, n * steps / seconds
    if backend == "cuda":
        from flatbody_env.env.core import EnvCore, configure
        from flatbody_env.integrators import cuda

        dev = cuda.require()
        config = configure(**kwargs)
        core = EnvCore(config, n, max_episode_steps=400, autoreset="same", backend="cuda")
        core.reset(seeds=list(range(n)), stagger=True)
        dA = dev.to_device(rng.uniform(-1, 1, (steps, n) + config.action_space.shape).astype(np.float32))
        core.step(dA[0])  # compile / warm
        dev.synchronize()

        def block() -> None:
            for k in range(steps):
                core.step(dA[k])
            dev.synchronize()

        return config.stepper.method, n * steps / best_of(block, repeats, warm=False)
    raise ValueError(f"backend: no whole-env row for {backend!r} (allowed: {', '.join(ENV_BACKENDS)})")


def run(
    *,
    sizes=DEFAULT_SIZES,
    methods=DEFAULT_METHODS,
    steps: int = 10,
    repeats: int = 3,
    only=None,
    progress=None,
    envs=None,
) -> dict:
    """Every backend here (or those of ``only`` among them) × ``methods`` × ``sizes`` (dynamics only), then the
    whole env step on those of :data:`ENV_BACKENDS` × ``sizes``: ``{"rows", "settings", "left_out"}``;
    ``progress(row)`` is called after each row."""
    import numba

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

    def add(what, backend, method, n, rate, env=""):
        row = {
            "what": what,
            "env": env,
            "backend": backend,
            "method": method,
            "n": n,
            "steps_per_s": rate,
            "device_name": device_names[backend],
        }
        rows.append(row)
        if progress is not None:
            progress(row)

    for backend in names:
        for method in methods:
            for n in sizes:
                add(WHAT, backend, method, int(n), measure(backend, method, int(n), steps=steps, repeats=repeats))
    from flatbody_env.env.registration import V1_IDS

    for backend in [b for b in names if b in ENV_BACKENDS]:
        for env_id in envs or (V1_IDS if backend == "cuda" else ("FlatBody-v1",)):
            for n in sizes:
                method, rate = measure_env(backend, int(n), steps=steps, repeats=repeats, env_id=env_id)
                add(WHAT_ENV, backend, method, int(n), rate, env_id)
    settings = {
        "dt": DT,
        "rk4_step": RK4_STEP,
        "dop853_rtol": DOP853_TOL,
        "dop853_atol": DOP853_TOL,
        "steps": steps,
        "repeats": repeats,
        "threads": int(numba.get_num_threads()),
    }
    return {"rows": rows, "settings": settings, "left_out": notes}


def tables(result: dict) -> list[Table]:
    """The rows of a run (the terminal's text), the backends left out under them."""
    rows = [
        [
            "dynamics" if r["what"] == WHAT else "whole env",
            r.get("env", "") or "—",
            r["backend"],
            r["method"],
            str(r["n"]),
            f"{r['steps_per_s']:.4g}",
            r["device_name"],
        ]
        for r in result["rows"]
    ]
    return [
        Table(
            columns=["what", "env", "backend", "method", "N", "body-steps/s", "device"],
            rows=rows,
            notes=[f"left out: {note}" for note in result.get("left_out", ())],
            block=None,
        )
    ]


def report(result: dict, name: str) -> Report:
    """``NAME.json`` (``result``), ``NAME.csv`` (the rows), ``NAME.png`` (drawn from the JSON) and the table."""
    return Report(
        name=name,
        record=result,
        header=list(ROW_KEYS),
        rows=[[r.get(k, "") for k in ROW_KEYS] for r in result["rows"]],
        chart=plot,
        tables=tables(result),
    )


BACKEND_COLOURS = {"cpu-serial": "#1f77b4", "cpu-parallel": "#2ca02c", "cuda": "#d62728"}
"""The chart's colour of each backend."""
ENV_MARKERS = ("s", "^", "v", "D", "P", "X", "h")
"""The chart's marker of each env id of the whole-env rows, in order of appearance."""

GPU_CAPTION = (
    "Colour: where it ran (the backend and its device). Line style: what was timed: the dynamics alone (the "
    "integrator's step of N bodies, no observation,\nreward or reset), RK4 solid, DOP853 dashed; the whole env step "
    "(controls, dynamics, observation, reward, termination, autoresets) dotted, one marker\nper env id. "
    "body-steps/s: N × steps / wall time, the best of the timed blocks; a CUDA block ends with a device "
    "synchronisation."
)
"""The chart's caption: colours, line styles, what a body-step is."""


def plot(json_path: str | Path, png_path: str | Path) -> None:
    """Body-steps/s against N from the saved JSON (log–log): colour = backend, line style = what was timed
    (dynamics: RK4 solid, DOP853 dashed; whole env step: dotted, a marker per env id); legends below."""
    from matplotlib.lines import Line2D

    from flatbody_env.figures import chart

    result = validation.read_json("--plot-only", json_path)
    rows = result["rows"]
    keys = list(dict.fromkeys((r["what"], r.get("env", ""), r["backend"], r["method"]) for r in rows))
    env_ids = list(dict.fromkeys(k[1] for k in keys if k[0] != WHAT))
    marker_of = {e: ENV_MARKERS[i % len(ENV_MARKERS)] for i, e in enumerate(env_ids)}
    with chart(png_path, size=(9.6, 6.6)) as c:
        ax = c.ax
        for what, env, backend, method in keys:
            sel = sorted(
                (
                    r
                    for r in rows
                    if (r["what"], r.get("env", ""), r["backend"], r["method"]) == (what, env, backend, method)
                ),
                key=lambda r: r["n"],
            )
            whole = what != WHAT
            ax.plot(
                [r["n"] for r in sel],
                [r["steps_per_s"] for r in sel],
                marker=marker_of[env] if whole else "o",
                ms=5,
                linestyle=":" if whole else ("-" if method == "RK4" else "--"),
                color=BACKEND_COLOURS.get(backend, "#000000"),
            )
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("bodies N")
        ax.set_ylabel("body-steps / s (higher is better)")
        ax.grid(True, which="major", alpha=0.3)
        ax.set_title(
            f"one env step of N bodies, dt = {DT:g}: RK4 h = dt/4, DOP853 tol {DOP853_TOL:g}; best of "
            f"{result['settings']['repeats']} blocks of {result['settings']['steps']} steps"
        )
        devices = {r["backend"]: r["device_name"] for r in rows}
        where = [
            Line2D([], [], color=BACKEND_COLOURS.get(b, "#000000"), lw=6, label=f"{b} ({devices[b]})") for b in devices
        ]
        methods = list(dict.fromkeys(k[3] for k in keys if k[0] == WHAT))
        what = [
            Line2D([], [], color="0.3", marker="o", ls="-" if m == "RK4" else "--", label=f"dynamics alone, {m}")
            for m in methods
        ]
        what += [
            Line2D([], [], color="0.3", marker=marker_of[e], ls=":", label=f"whole env step{', ' + e if e else ''}")
            for e in env_ids
        ]
        rows_needed = max(len(where), len(what))
        blank = [Line2D([], [], alpha=0.0, label="") for _ in range(2 * rows_needed)]
        handles = where + blank[: rows_needed - len(where)] + what + blank[: rows_needed - len(what)]
        c.legend(handles, [h.get_label() for h in handles], where="below", ncol=2)
        c.title("flatbody bench gpu: body-steps per second against the number of bodies")
        c.caption(GPU_CAPTION)


__all__ = [
    "BACKENDS",
    "BACKEND_COLOURS",
    "DEFAULT_METHODS",
    "DEFAULT_SIZES",
    "ENV_BACKENDS",
    "ROW_KEYS",
    "WHAT",
    "WHAT_ENV",
    "backends",
    "measure",
    "measure_env",
    "plot",
    "report",
    "run",
    "tables",
]
