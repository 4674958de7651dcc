"""Run by test_cuda_simulator.py in a child process with NUMBA_ENABLE_CUDASIM=1 (numba's CUDA simulator must be
switched on before numba.cuda is imported): the CUDA kernels against the CPU kernels; prints one JSON report."""

from __future__ import annotations

import json
import os
import types

import numpy as np

from flatbody_env import load_scene, simulate_batch
from flatbody_env.integrators import IntegrationError
from flatbody_env.integrators import batch_solve as bs
from flatbody_env.integrators import cuda
from flatbody_env.integrators.compiled_methods import kernel_params
from flatbody_env.physics.state import pack

STEPS = {
    "RK4": 0.02,
    "splitting-strang": 0.01,
    "splitting-suzuki4": 0.04,
    "splitting-yoshida4": 0.02,
    "DOP853-numba": 0.0,
}


def _states() -> tuple[object, np.ndarray]:
    """Five bodies of the close-approach shape: three regular orbits, the close approach (fails with the fixed-step
    methods) and a fast spinner."""
    scene = load_scene("close-approach")
    y = pack(scene.state)
    rng = np.random.default_rng(0)
    Y0 = np.tile(y, (5, 1))
    Y0[:3, 2] += 0.5 + 0.1 * rng.random(3)
    Y0[:3, :7] += 0.02 * rng.normal(size=(3, 7))
    Y0[4, 2] += 6.0
    return scene.body, Y0


def _diff(a: np.ndarray, b: np.ndarray) -> float:
    """Max |a − b| where both are finite; inf where NaN patterns differ."""
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return float("inf")
    ok = ~np.isnan(a)
    return float(np.max(np.abs(a[ok] - b[ok]))) if ok.any() else 0.0


def _device_functions() -> dict:
    """The device functions the integrators' and the env's kernels reach, walked through the globals their code reads:
    how many, any function left un-retargeted (a CPU dispatcher or plain Python, which the simulator would run silently),
    and any numpy ufunc their code reads through a module (numba-cuda cannot lower ``np.sqrt`` on a scalar; the simulator
    runs numpy itself, so only this check sees it without a GPU)."""
    from numba.core.dispatcher import Dispatcher

    from flatbody_env.env import transition
    from flatbody_env.integrators.jit import _names

    seen: set[int] = set()
    left: list[str] = []
    ufuncs: set[str] = set()
    todo = [kernel.py_func for kernel in cuda._kernels()]
    todo += [cuda.kernel(k).py_func for k in (transition._step_kernel, transition._reset_kernel)]
    while todo:
        fn = todo.pop()
        for name in _names(fn.__code__):
            value = fn.__globals__.get(name)
            if isinstance(value, types.ModuleType):
                ufuncs.update(
                    f"{fn.__name__}: {name}.{attr}"
                    for attr in fn.__code__.co_names
                    if isinstance(getattr(value, attr, None), np.ufunc)
                )
            if isinstance(value, (Dispatcher, types.FunctionType)):
                left.append(f"{fn.__name__}.{name}")
            elif hasattr(value, "py_func") and id(value) not in seen:
                seen.add(id(value))
                todo.append(value.py_func)
    return {"count": len(seen), "not_retargeted": sorted(left), "numpy_ufuncs": sorted(ufuncs)}


def main() -> dict:
    report = {
        "simulated": cuda.simulated(),
        "available": cuda.is_available(),
        "device": cuda.device_name(),
        "methods": {},
    }
    body, Y0 = _states()
    P = kernel_params(body)
    n = Y0.shape[0]
    times = np.array([0.0, 0.4, 0.8])
    u = np.zeros(4)
    etol = np.full(n, 1e-2)
    for name, h in STEPS.items():
        kind, coeffs = bs.KIND[name]
        OUT = np.empty((n, times.size, 11))
        ST, NF, TF = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n)
        bs.batch_solve(kind, coeffs, Y0, times, u, P, h, 1e-10, 1e-10, etol, 10**7, OUT, ST, NF, TF)
        gOUT, gST, gNF, gTF = cuda.solve(
            name, Y0, times, u, P, h=h, rtol=1e-10, atol=1e-10, energy_tol=etol, max_nfev=10**7, threads_per_block=4
        )
        # one environment step, controls on two bodies
        Ys = np.ascontiguousarray(Y0.T)
        U = np.zeros((4, n))
        U[:, 1] = [0.1, -0.2, 0.05, 0.3]
        U[3, 2] = -0.5
        O1, S1, N1 = np.empty_like(Ys), np.zeros(n, np.int64), np.zeros(n, np.int64)
        bs.batch_env_step_serial(kind, coeffs, Ys, U, P, 0.05, h / 4, 1e-11, 1e-11, 1e-3, O1, S1, N1)
        d_Y, d_U, d_P = cuda.cuda.to_device(Ys), cuda.cuda.to_device(U), cuda.cuda.to_device(P)
        d_OUT, d_ST, d_NF = cuda.env_step(
            name, d_Y, d_U, d_P, 0.05, h=h / 4, rtol=1e-11, atol=1e-11, energy_tol=1e-3, threads_per_block=2
        )
        report["methods"][name] = {
            "solve_diff": _diff(OUT, gOUT),
            "solve_status_cpu": ST.tolist(),
            "solve_status_cuda": gST.tolist(),
            "solve_nfev_equal": bool(np.array_equal(NF, gNF)),
            "solve_tfail_diff": _diff(TF, gTF),
            "env_diff": _diff(O1, d_OUT.copy_to_host()),
            "env_status_cpu": S1.tolist(),
            "env_status_cuda": d_ST.copy_to_host().tolist(),
            "env_nfev_equal": bool(np.array_equal(N1, d_NF.copy_to_host())),
        }
    # DOP853 out of budget on every body: the budget status on both targets
    OUT = np.empty((n, times.size, 11))
    ST, NF, TF = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n)
    bs.batch_solve(bs.DOP853_KIND, bs.STRANG, Y0, times, u, P, 0.0, 1e-10, 1e-10, etol, 30, OUT, ST, NF, TF)
    gOUT, gST, gNF, gTF = cuda.solve(
        "DOP853-numba", Y0, times, u, P, h=0.0, rtol=1e-10, atol=1e-10, energy_tol=etol, max_nfev=30
    )
    report["dop853_budget"] = {
        "status_cpu": ST.tolist(),
        "status_cuda": gST.tolist(),
        "diff": _diff(OUT, gOUT),
        "nfev_equal": bool(np.array_equal(NF, gNF)),
    }
    on_cpu = simulate_batch(body, Y0[:3], times=[0.3, 0.6], method="RK4", step=0.05)
    on_gpu = simulate_batch(body, Y0[:3], times=[0.3, 0.6], method="RK4", step=0.05, device="cuda")
    report["simulate_batch"] = {
        "diff": _diff(on_cpu.state, on_gpu.state),
        "device": on_gpu.device,
        "status_equal": bool(np.array_equal(on_cpu.status, on_gpu.status)),
    }
    report["device_functions"] = _device_functions()
    report["env_step_budget"] = _env_step_budget(body, Y0, P)
    report["wall_time"] = _wall_time(body, Y0)
    return report


def _env_step_budget(body, Y0, P) -> dict:
    """A DOP853 env step with a budget of 30 RHS evaluations per body: the budget status and the kept states on both targets."""
    n = Y0.shape[0]
    Ys, U = np.ascontiguousarray(Y0.T), np.zeros((4, n))
    O1, S1, N1 = np.empty_like(Ys), np.zeros(n, np.int64), np.zeros(n, np.int64)
    bs.batch_env_step_serial(bs.DOP853_KIND, bs.STRANG, Ys, U, P, 0.5, 0.0, 1e-11, 1e-11, np.inf, O1, S1, N1, 30)
    d_OUT, d_ST, d_NF = cuda.env_step(
        "DOP853-numba",
        cuda.cuda.to_device(Ys),
        cuda.cuda.to_device(U),
        cuda.cuda.to_device(P),
        0.5,
        rtol=1e-11,
        atol=1e-11,
        max_nfev=30,
        threads_per_block=2,
    )
    unbounded = cuda.env_step(
        "DOP853-numba",
        cuda.cuda.to_device(Ys),
        cuda.cuda.to_device(U),
        cuda.cuda.to_device(P),
        0.5,
        rtol=1e-11,
        atol=1e-11,
        threads_per_block=2,
    )[2].copy_to_host()
    return {
        "status_cpu": S1.tolist(),
        "status_cuda": d_ST.copy_to_host().tolist(),
        "diff": _diff(O1, d_OUT.copy_to_host()),
        "nfev_equal": bool(np.array_equal(N1, d_NF.copy_to_host())),
        "nfev_unbounded": unbounded.tolist(),
    }


def _wall_time(body, Y0) -> dict:
    """``simulate_batch(device="cuda", max_wall_time=...)``: launches of bounded work with the clock read between them (the
    probe shortened to 100 evaluations, the simulator being slow): a batch that finishes equals the CPU's bit for bit;
    a horizon far beyond the time ends every body with the ``budget`` status, soon after the time is up."""
    import time

    from flatbody_env.integrators import budget

    budget.PROBE_NFEV = 100
    y = Y0[:3]
    cpu = simulate_batch(body, y, times=[0.3, 0.6], method="DOP853-numba", max_nfev=10**6)
    gpu = simulate_batch(
        body, y, times=[0.3, 0.6], method="DOP853-numba", max_nfev=10**6, max_wall_time=600.0, device="cuda"
    )
    t0 = time.perf_counter()
    out = simulate_batch(body, y, times=[1e4], method="DOP853-numba", max_nfev=10**7, max_wall_time=2.0, device="cuda")
    took = time.perf_counter() - t0
    try:  # fixed steps know their work: a timed launch of 256 steps predicts far more than 2 s, refused up front
        simulate_batch(body, y, times=[1e4], method="RK4", step=0.01, max_nfev=10**8, max_wall_time=2.0, device="cuda")
        refused = ""
    except IntegrationError as exc:
        refused = f"{exc.kind}: {exc}"
    return {
        "fixed_refused": refused,
        "finished": {
            "diff": _diff(cpu.state, gpu.state),
            "status_cpu": cpu.status.tolist(),
            "status_cuda": gpu.status.tolist(),
            "nfev_equal": bool(np.array_equal(cpu.nfev, gpu.nfev)),
            "launches": gpu.extra["launches"],
        },
        "over": {
            "status": out.status.tolist(),
            "seconds": took,
            "launches": out.extra["launches"],
            "nfev": out.nfev.tolist(),
            "all_nan": bool(np.isnan(out.state).all()),
            "t_fail": out.t_fail.tolist(),
        },
    }


if __name__ == "__main__":
    assert os.environ.get("NUMBA_ENABLE_CUDASIM") == "1", "run with NUMBA_ENABLE_CUDASIM=1"
    print(json.dumps(main()))
