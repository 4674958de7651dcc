"""The CUDA target without a GPU: numba's CUDA simulator runs the device kernels (compiled from the same
plain-Python source as the CPU kernels) and must agree with the CPU kernels; real-GPU checks are marked ``gpu``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
FIXED = ("RK4", "splitting-strang", "splitting-suzuki4", "splitting-yoshida4")


@pytest.fixture(scope="module")
def report():
    """The simulator run (a child process: NUMBA_ENABLE_CUDASIM must be set before numba.cuda is imported)."""
    env = dict(
        os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("cuda_sim_check.py"))],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_the_simulator_stands_in_for_a_gpu(report):
    assert report["simulated"] and report["available"] and report["device"] == "simulator"


@pytest.mark.parametrize("method", FIXED + ("DOP853-numba",))
def test_cuda_trajectories_equal_the_cpu_kernels(report, method):
    """N = 5 bodies, two output intervals: states to 1e-14 (bit-identical in practice), the same statuses, nfev and failure times."""
    r = report["methods"][method]
    assert r["solve_diff"] <= 1e-14
    assert r["solve_status_cuda"] == r["solve_status_cpu"]
    assert r["solve_nfev_equal"] and r["solve_tfail_diff"] <= 1e-14
    if method in FIXED:  # the fast spinner fails: the failure path ran on both targets
        assert r["solve_status_cpu"][4] != 0 and r["solve_status_cpu"][:4].count(0) >= 3


@pytest.mark.parametrize("method", FIXED + ("DOP853-numba",))
def test_cuda_env_step_equals_the_cpu_kernels(report, method):
    """One launch per env step on device arrays (controls on two bodies): the states, statuses and nfev of the CPU batch step."""
    r = report["methods"][method]
    assert r["env_diff"] <= 1e-14
    assert r["env_status_cuda"] == r["env_status_cpu"]
    assert r["env_nfev_equal"]


def test_dop853_budget_status_on_both_targets(report):
    r = report["dop853_budget"]
    assert set(r["status_cpu"]) == {8} and r["status_cuda"] == r["status_cpu"]  # 8 = "budget"
    assert r["nfev_equal"] and r["diff"] == 0.0  # NaN rows in the same places on both


def test_simulate_batch_on_cuda_equals_cpu(report):
    r = report["simulate_batch"]
    assert r["device"] == "cuda" and r["status_equal"] and r["diff"] <= 1e-14


def test_cuda_env_step_has_a_budget_of_evaluations(report):
    """A kernel cannot read the clock: an env step's launch is bounded by each body's budget of RHS evaluations, as on the CPU."""
    r = report["env_step_budget"]
    assert set(r["status_cpu"]) == {8} and r["status_cuda"] == r["status_cpu"]  # 8 = "budget"
    assert r["nfev_equal"] and r["diff"] == 0.0
    assert max(r["nfev_unbounded"]) > 30  # without the budget the same step takes more


def test_simulate_batch_on_cuda_honours_the_wall_clock_budget(report):
    """Launches of bounded work, the clock read between them: a batch that finishes in time is the CPU's bit for bit, and a
    horizon far beyond the time ends every body with the ``budget`` status soon after the time is up (2 s; a launch is sized
    to the time left, the simulator's speed measured as the GPU's would be)."""
    done, over = report["wall_time"]["finished"], report["wall_time"]["over"]
    assert done["status_cuda"] == done["status_cpu"] == [0, 0, 0]
    assert done["diff"] == 0.0 and done["nfev_equal"]
    assert done["launches"] >= 2  # the probe's 100 evaluations were not enough: re-launched with a larger budget
    assert over["status"] == [8, 8, 8] and over["all_nan"]
    assert over["launches"] >= 3 and max(over["nfev"]) < 10**7
    assert over["seconds"] < 2.0 + 6.0, (
        over
    )  # the last launch is predicted to fit the time left; slack for a loaded machine
    assert report["wall_time"]["fixed_refused"].startswith("budget: "), report[
        "wall_time"
    ]  # RK4 over the time: refused up front


def test_every_device_function_is_retargeted(report):
    """The kernels reach only device functions (:func:`flatbody_env.integrators.jit.retarget` on the CUDA target): no CPU
    dispatcher or plain-Python function is left in the globals their code reads (the simulator would run one silently),
    and no numpy ufunc, which numba-cuda 0.30 cannot lower on scalars (device code reads ``np`` as ``cuda.DEVICE_NUMPY``;
    the task's ``score_kernel`` calls ``np.sqrt``)."""
    r = report["device_functions"]
    assert r["not_retargeted"] == [] and r["count"] >= 60
    assert r["numpy_ufuncs"] == []


def test_no_function_hands_out_a_cuda_local_array():
    """A CUDA local array lives as long as the function that allocates it: a function that returned one (or a tuple
    holding one) would hand its caller memory the GPU compiler may reuse for other arrays — which the simulator, whose
    local arrays are numpy arrays, never shows (the env's step kernel did so once: every step of every body ended on a
    real GPU while the simulator agreed bit for bit). Every function of the package that calls ``cuda.local.array`` is
    read here, and none returns a name bound to one, nor the call itself."""
    import ast
    from pathlib import Path

    import flatbody_env

    def is_alloc(node) -> bool:
        return isinstance(node, ast.Call) and ast.unparse(node.func).endswith("local.array")

    def returned(node):  # what a return statement hands out: the value, or the items of a tuple or list
        if isinstance(node, (ast.Tuple, ast.List)):
            return [m for e in node.elts for m in returned(e.value if isinstance(e, ast.Starred) else e)]
        return [node]

    seen = 0
    for path in Path(flatbody_env.__file__).parent.rglob("*.py"):
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, ast.FunctionDef) or not any(is_alloc(n) for n in ast.walk(fn)):
                continue
            seen += 1
            local = {t.id for n in ast.walk(fn) if isinstance(n, ast.Assign) and is_alloc(n.value)
                     for t in n.targets if isinstance(t, ast.Name)}  # fmt: skip
            for ret in (n for n in ast.walk(fn) if isinstance(n, ast.Return) and n.value is not None):
                leaked = [n for n in returned(ret.value) if is_alloc(n) or (isinstance(n, ast.Name) and n.id in local)]
                assert not leaked, f"{path.name}:{ret.lineno} {fn.name} returns a CUDA local array"
    assert seen >= 4  # the kernels of integrators/cuda.py and env/transition.py, the device initial step


def _a_kernel():  # a module-level function for the cache's locator (its source file is this one)
    return None


def test_the_kernel_cache_is_keyed_by_the_kernels_sources_and_never_stops_a_launch(tmp_path, monkeypatch):
    """The env's CUDA kernels are cached on disk (≈ 40 s of compiling on first use): the key holds a digest of every
    source file of the kernel layers, so an edit beneath a kernel compiles it anew, and an entry that cannot be read or
    written is a warning and a compile, never an error at the launch."""
    from numba.cuda.dispatcher import CUDACache

    from flatbody_env.integrators import cuda

    pkg = tmp_path / "pkg"
    for sub in ("env", "integrators", "service"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "m.py").write_text("x = 1\n")
    monkeypatch.setattr(cuda, "_PACKAGE", pkg)
    digest = cuda.source_digest.__wrapped__
    first = digest()
    (pkg / "service" / "m.py").write_text("x = 2\n")  # not a kernel layer
    assert digest() == first
    (pkg / "integrators" / "m.py").write_text("x = 2\n")
    assert digest() != first

    cache = cuda._cache_class()(_a_kernel)
    monkeypatch.setattr(CUDACache, "_index_key", lambda self, sig, codegen: ("sig", "codegen"))
    assert cache._index_key(None, None) == ("sig", "codegen", cuda.source_digest())

    def broken(*args, **kwargs):
        raise OSError("disk gone")

    monkeypatch.setattr(CUDACache, "load_overload", broken)
    monkeypatch.setattr(CUDACache, "save_overload", broken)
    with pytest.warns(UserWarning, match="not read .*disk gone.*compiling"):
        assert cache.load_overload(None, None) is None
    with pytest.warns(UserWarning, match="not written .*disk gone"):
        cache.save_overload(None, object())


def _power_of_ten(x: float) -> str:
    mantissa, exponent = f"{x:.1e}".split("e")
    return f"{mantissa} × 10{str(int(exponent)).translate(str.maketrans('-0123456789', '⁻⁰¹²³⁴⁵⁶⁷⁸⁹'))}"


def test_the_gpu_equality_figures_in_the_docs_are_the_saved_report():
    """docs/gpu.md's figures of every v1 id on an H200 against the CPU are those of the report the GPU test wrote
    (``agents/data/gpu/device_env_h200.json``): every id in SAME_STEP, FlatBody-v1 in NEXT_STEP too, every body's ends
    agreeing, and the largest differences the page quotes."""
    import json
    from pathlib import Path

    from flatbody_env.env.registration import V1_IDS

    root = Path(__file__).resolve().parents[2]
    report = json.loads((root / "agents/data/gpu/device_env_h200.json").read_text())
    assert sorted(report) == sorted([f"{e}:SameStep" for e in V1_IDS] + ["FlatBody-v1:NextStep"])
    assert all(r["ends_agree"] == r["bodies"] and r["resets"] >= r["bodies"] for r in report.values())
    draws = max(max(r["reset_target"], r["reset_state"]) for r in report.values())
    states = max(r["state"] for r in report.values())
    text = " ".join((root / "docs/gpu.md").read_text().split())
    assert f"≤ {_power_of_ten(draws)} for the draws, ≤ {_power_of_ten(states)} for the states" in text


def test_device_numpy_is_numpy_with_math_scalars():
    """``np`` in device code: numpy's own attributes, the scalar ufuncs as their math twins: the correctly rounded ones
    (sqrt, abs) give numpy's float64 results, the others (libm's atan2) agree to an ulp."""
    import math

    from flatbody_env.integrators import cuda

    dnp = cuda.DEVICE_NUMPY
    assert dnp.uint64 is np.uint64 and dnp.inf == np.inf and dnp.float64 is np.float64
    assert not [
        k
        for k in dir(dnp)
        if isinstance(getattr(dnp, k), np.ufunc) and not k.startswith("_") and k in cuda._SCALAR_UFUNCS
    ]
    rng = np.random.default_rng(0)
    for x in np.concatenate([rng.uniform(1e-3, 10.0, 200), [0.0, 1.0, 2.0]]):
        assert dnp.sqrt(x) == np.sqrt(x) and dnp.abs(-x) == np.abs(-x)
        assert abs(dnp.arctan2(x, 0.7) - np.arctan2(x, 0.7)) <= 2 * np.spacing(np.arctan2(x, 0.7))
    assert math.isnan(dnp.sqrt(float("nan")))


def _real_gpu() -> bool:
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
        return False
    from flatbody_env.integrators import cuda

    return cuda.is_available()


@pytest.mark.gpu
def test_real_gpu_agrees_with_the_cpu_kernels():
    """On a CUDA GPU: 4,096 bodies, 20 RK4 env steps and a DOP853 trajectory against the CPU kernels (FMA contraction on the
    GPU allows round-off differences)."""
    if not _real_gpu():
        pytest.skip("no CUDA GPU here")
    from flatbody_env import load_scene, simulate_batch
    from flatbody_env.integrators import batch_solve as bs
    from flatbody_env.integrators import cuda
    from flatbody_env.integrators.compiled_methods import kernel_params
    from flatbody_env.physics.state import pack

    scene = load_scene("default")
    rng = np.random.default_rng(0)
    n = 4096
    Y0 = np.tile(pack(scene.state), (n, 1))
    Y0[:, :7] += 0.05 * rng.normal(size=(n, 7))
    P = kernel_params(scene.body)
    Ys, U = np.ascontiguousarray(Y0.T), np.zeros((4, n))
    cpu = Ys.copy()
    dev = cuda.require()
    d_Y = dev.to_device(Ys)
    for _ in range(20):
        out, st, nf = np.empty_like(cpu), np.zeros(n, np.int64), np.zeros(n, np.int64)
        bs.batch_env_step_serial(bs.RK4_KIND, bs.STRANG, cpu, U, P, 0.05, 0.0125, 1e-11, 1e-11, np.inf, out, st, nf)
        cpu = out
        d_Y, d_st, _ = cuda.env_step("RK4", d_Y, dev.to_device(U), dev.to_device(P), 0.05, h=0.0125)
        assert (d_st.copy_to_host() == st).all()
    assert np.max(np.abs(d_Y.copy_to_host() - cpu)) <= 1e-11
    a = simulate_batch(scene.body, Y0[:256], times=[1.0, 2.0], method="DOP853-numba", device="cpu")
    b = simulate_batch(scene.body, Y0[:256], times=[1.0, 2.0], method="DOP853-numba", device="cuda")
    assert (a.status == b.status).all() and np.nanmax(np.abs(a.state - b.state)) <= 1e-9
