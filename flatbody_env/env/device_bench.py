"""Body-steps per second of the **whole** env step against N, on every backend this machine has (``flatbody bench gpu``
adds these rows to :mod:`flatbody_env.integrators.batch_bench`'s dynamics-only rows).

What is timed (``what`` = :data:`WHAT_ENV`): random actions in [−1, 1], the controls, the dynamics, the task's
observation, reward terms, termination and autoresets, ``FlatBody-v0``'s defaults (its DOP853), 400-step episodes
started with staggered clocks so that resets fall in every step; the best of ``repeats`` blocks of ``steps`` steps
after one untimed step (compilation).

* ``cpu-serial`` — :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` (SAME_STEP) ``step``, one thread (the
  CPU env as users run it);
* ``cuda`` — :class:`~flatbody_env.env.device.DeviceBatch` on CUDA: one launch per step
  (:func:`flatbody_env.integrators.cuda.env_step` with ``task=``), actions and every array on the device, with the
  per-step read of the two-integer error flag (the kernels ``FlatBodyTorchVectorEnv(device="cuda")`` launches; its
  tensor wrapping is not timed). numba's simulator is never timed.
"""

from __future__ import annotations

import time

import numpy as np

WHAT_ENV = "env step, whole (controls, dynamics, observation, rewards, termination, autoresets)"
BACKENDS = ("cpu-serial", "cuda")


def measure_env(backend: str, n: int, *, steps: int, repeats: int) -> tuple[str, float]:
    """(method, body-steps per second) of the whole env step of ``n`` bodies on ``backend`` (module docstring)."""
    from gymnasium.vector import AutoresetMode

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    rng = np.random.default_rng(0)
    if backend == "cpu-serial":
        env = FlatBodyVectorEnv(num_envs=n, autoreset_mode=AutoresetMode.SAME_STEP)
        env.reset(seed=0, options={"stagger": True})
        blocks = [rng.uniform(-1, 1, (steps + 1, n) + env.single_action_space.shape).astype(np.float32) for _ in range(repeats)]
        env.step(blocks[0][0])  # compile / warm
        best = float("inf")
        for A in blocks:
            t0 = time.perf_counter()
            for k in range(steps):
                env.step(A[k])
            best = min(best, time.perf_counter() - t0)
        method = env.stepper.method
        env.close()
        return method, n * steps / best
    if backend == "cuda":
        from flatbody_env.env.device import DeviceBatch
        from flatbody_env.env.env import FlatBodyEnv
        from flatbody_env.integrators import cuda

        dev = cuda.require()
        p = FlatBodyEnv()
        batch = DeviceBatch(p, n, 400, same_step=True, backend="cuda")
        batch.reset(seed=0, stagger=True)
        dA = dev.to_device(rng.uniform(-1, 1, (steps, n) + p.action_space.shape).astype(np.float32))
        batch.step(dA[0])  # compile / warm
        dev.synchronize()
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            for k in range(steps):
                batch.step(dA[k])
            dev.synchronize()
            best = min(best, time.perf_counter() - t0)
        return batch.method, n * steps / best
    raise ValueError(f"backend: no whole-env row for {backend!r} (allowed: cpu-serial, cuda)")


def run(backends, device_names: dict, *, sizes, steps: int, repeats: int, progress=None) -> list[dict]:
    """Rows ``{"what", "backend", "method", "n", "steps_per_s", "device_name"}`` of the whole env step for each of
    ``backends`` (those of :data:`BACKENDS` among them) × ``sizes``."""
    rows = []
    for backend in [b for b in backends if b in BACKENDS]:
        for n in sizes:
            method, rate = measure_env(backend, int(n), steps=steps, repeats=repeats)
            row = {"what": WHAT_ENV, "backend": backend, "method": method, "n": int(n), "steps_per_s": rate,
                   "device_name": device_names[backend]}
            rows.append(row)
            if progress is not None:
                progress(row)
    return rows


__all__ = ["BACKENDS", "WHAT_ENV", "measure_env", "run"]
