"""simulate_batch: N bodies equal N calls of simulate; per-body failures; bad input; no GPU → one clear error."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import flatbody_env.batch as batch
from flatbody_env import IntegrationError, Scene, load_scene, simulate, simulate_batch
from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.potentials import CustomPotential, V2
from flatbody_env.physics.state import STATE_NAMES, pack, unpack

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = [
    ("RK4", 0.01),
    ("splitting-strang", 0.01),
    ("splitting-suzuki4", 0.02),
    ("splitting-yoshida4", 0.02),
    ("DOP853-numba", None),
]


def _states(scene, n, seed):
    rng = np.random.default_rng(seed)
    Y0 = np.tile(pack(scene.state), (n, 1))
    Y0[:, :7] += 0.05 * rng.normal(size=(n, 7))
    return Y0


def _simulate_one(scene, y, times, method, step, **kw):
    return simulate(
        Scene(name="row", body=scene.body, state=unpack(y)),
        t_end=float(times[-1]),
        times=times,
        method=method,
        step=step,
        model="two-polar",
        **kw,
    )


@pytest.mark.parametrize("method,step", SETTINGS, ids=[m for m, _ in SETTINGS])
def test_batch_equals_simulate_per_body(method, step):
    """Body i of the batch is simulate(y0[i]) to 1e-12 (the same kernels: in fact bit for bit), same nfev; times without 0."""
    scene = load_scene("default")
    Y0 = _states(scene, 3, seed=1)
    times = np.array([0.25, 0.5, 1.0, 1.5])
    bt = simulate_batch(scene.body, Y0, times=times, method=method, step=step)
    assert bt.state.shape == (3, 4, 11) and bt.t.tolist() == times.tolist()
    assert bt.ok.all() and bt.kinds == ["ok"] * 3 and np.isnan(bt.t_fail).all()
    for i in range(3):
        tr = _simulate_one(scene, Y0[i], times, method, step)
        assert np.max(np.abs(tr.y.T - bt.state[i])) <= 1e-12
        assert tr.nfev == bt.nfev[i]
    np.testing.assert_array_equal(bt.series("rho"), bt.state[:, :, STATE_NAMES.index("rho")])


@pytest.mark.parametrize("method,step,kind", [("RK4", 0.01, "under-resolved"), ("splitting-strang", 0.01, "energy")])
def test_one_failed_body_does_not_stop_the_others(method, step, kind):
    """Close approach: body 0 fails as simulate does (same kind and time), its rows from the failure on are NaN;
    body 1 (far from λ = μ) runs through and equals simulate."""
    scene = load_scene("close-approach")
    y = pack(scene.state)
    Y0 = np.array([y, y])
    Y0[1, 2] += 0.5
    times = np.linspace(1.0, 6.0, 6)
    bt = simulate_batch(scene.body, Y0, times=times, method=method, step=step)
    assert bt.kinds == [kind, "ok"]
    with pytest.raises(IntegrationError) as err:
        _simulate_one(scene, Y0[0], times, method, step)
    assert err.value.kind == kind and bt.t_fail[0] == pytest.approx(err.value.t, abs=1e-12)
    bad = np.isnan(bt.state[0]).all(axis=1)
    first = int(np.searchsorted(times, bt.t_fail[0]))  # the row whose interval held the failure
    assert not bad[:first].any() and bad[first:].all()
    tr = _simulate_one(scene, Y0[1], times, method, step)
    assert np.max(np.abs(tr.y.T - bt.state[1])) <= 1e-12


def test_dop853_budget_is_per_body():
    scene = load_scene("default")
    bt = simulate_batch(scene.body, _states(scene, 2, seed=2), times=[5.0], method="DOP853-numba", max_nfev=50)
    assert bt.kinds == ["budget", "budget"] and np.isnan(bt.state).all()
    assert (bt.nfev > 50).all()


def test_only_t0_returns_the_initial_states():
    scene = load_scene("default")
    Y0 = _states(scene, 2, seed=3)
    bt = simulate_batch(scene.body, Y0, times=[0.0], method="RK4", step=0.1)
    np.testing.assert_array_equal(bt.state[:, 0], Y0)
    assert bt.nfev.tolist() == [0, 0]


def _bad_y0(Y0, what):
    """y0 variants named in the table above (strings stand for arrays built from good states)."""
    bad = Y0.copy()
    if what == "row":
        return Y0[0].tolist()
    if what == "nan":
        bad[0, 3] = np.nan
    elif what == "lambda<0":
        bad[1, 7] = -1.0
    elif what == "p_rho big":
        bad[0, 6] = 2e6
    elif what == "lambda=mu":
        bad[1, 7] = bad[1, 8]
    return bad


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"y0": np.ones((2, 10))}, r"y0: expected an array of shape \(nx11\)"),
        ({"y0": np.zeros((0, 11))}, r"y0: must hold 1 to"),
        ({"y0": "row"}, r"y0: expected an array of shape \(nx11\), got shape \(11,\)"),
        ({"y0": "nan"}, r"y0: must hold finite numbers"),
        ({"y0": "lambda<0"}, r"y0\[1\]\.lambda: must lie in \[1e-06, 1e\+06\]"),
        ({"y0": "p_rho big"}, r"y0\[0\]\.p_rho: must lie in \[-1e\+06, 1e\+06\]"),
        ({"y0": "lambda=mu"}, r"y0\[1\]\.lambda: must differ from mu"),
        ({"times": [1.0, 0.5]}, r"times: must be strictly increasing"),
        ({"times": [-1.0]}, r"times: must each lie in \[0, 1e\+06\], got -1\.0"),
        ({"times": []}, r"times: must hold 1 to 100000 times"),
        ({"method": "DOP853"}, r"method: .*DOP853-numba"),
        ({"method": "RK4", "step": None}, r"step: RK4 is a fixed-step method"),
        ({"method": "DOP853-numba", "step": 0.1}, r"step: DOP853-numba is adaptive"),
        ({"step": -0.1}, r"step: must be > 0"),
        ({"rtol": 2.0, "method": "DOP853-numba", "step": None}, r"rtol: must lie in"),
        ({"energy_tol": -1.0}, r"energy_tol: must be a number > 0 or inf"),
        ({"device": "tpu"}, r"device: .*cpu.*cuda"),
        ({"body": "default"}, r"body: expected a flatbody_env.Body"),
    ],
)
def test_bad_input_names_the_field(kwargs, match):
    scene = load_scene("default")
    Y0 = _states(scene, 2, seed=4)
    y0 = kwargs.pop("y0", Y0)
    if isinstance(y0, str):
        y0 = _bad_y0(Y0, y0)
    args = {"body": scene.body, "times": [0.5, 1.0], "method": "RK4", "step": 0.05}
    args.update(kwargs)
    body = args.pop("body")
    with pytest.raises(ValueError, match=match):
        simulate_batch(body, y0, **args)


def test_bodies_the_kernels_cannot_run_are_refused():
    scene = load_scene("default")
    Y0 = _states(scene, 1, seed=5)
    custom = Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=CustomPotential(value=lambda l, m, r: 0.5 * (l * l + m * m), gradient=lambda l, m, r: (l, m, 0.0)),
    )
    with pytest.raises(ValueError, match="potential: RK4 is compiled and needs a built-in potential"):
        simulate_batch(custom, Y0, times=[1.0], method="RK4", step=0.1)
    aniso = Body(inertia=Inertia(J1=1.2, J2=0.8, J3=1.0), potential=V2(c=1.0, d=1.0))
    with pytest.raises(ValueError, match="body: splitting-strang .* needs J1 = J2"):
        simulate_batch(aniso, Y0, times=[1.0], method="splitting-strang", step=0.1)


def test_hostile_sizes_are_refused_before_allocation(monkeypatch):
    """N · T · 11 floats above the cap (lowered here so the test allocates nothing large) and N above the body cap."""
    scene = load_scene("default")
    Y0 = _states(scene, 4, seed=6)
    monkeypatch.setattr(batch, "MAX_OUTPUT_FLOATS", 4 * 10 * 11)
    with pytest.raises(ValueError, match=r"y0, times: N \* T \* 11 = 4 \* 11 \* 11 floats exceeds the limit"):
        simulate_batch(scene.body, Y0, times=np.linspace(0.1, 1.0, 10), method="RK4", step=0.1)
    monkeypatch.setattr(batch, "MAX_BODIES", 3)
    with pytest.raises(ValueError, match="y0: must hold 1 to 3 states"):
        simulate_batch(scene.body, Y0, times=[1.0], method="RK4", step=0.1)


def test_fixed_step_budget_is_refused_up_front():
    scene = load_scene("default")
    with pytest.raises(IntegrationError) as err:
        simulate_batch(scene.body, _states(scene, 2, seed=7), times=[100.0], method="RK4", step=1e-3, max_nfev=1000)
    assert err.value.kind == "budget"


def test_batch_methods_are_the_kernels_methods():
    from flatbody_env.integrators.batch_solve import BATCH_METHODS

    assert batch.BATCH_METHODS == BATCH_METHODS


def test_cuda_without_a_gpu_is_one_clear_error():
    """Without a CUDA target (numba.cuda made unimportable, as numba-cuda on numpy 2.5 is; or no GPU), device="cuda"
    raises one error that names the fix; the rest of the package imports and runs."""
    code = (
        "import sys\n"
        "sys.modules['numba.cuda'] = None\n"
        "import numpy as np\n"
        "from flatbody_env import simulate_batch, load_scene, pack\n"
        "from flatbody_env.integrators.cuda import CudaUnavailableError, is_available\n"
        "sc = load_scene('default')\n"
        "assert not is_available()\n"
        "try:\n"
        "    simulate_batch(sc.body, [pack(sc.state)], times=[0.1], method='RK4', step=0.05, device='cuda')\n"
        "except CudaUnavailableError as exc:\n"
        "    print(exc)\n"
        "bt = simulate_batch(sc.body, [pack(sc.state)], times=[0.1], method='RK4', step=0.05)\n"
        "print(bt.kinds)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    first, second = proc.stdout.strip().splitlines()
    assert first.startswith("device: ") and 'pip install "flatbody[gpu]" on a machine with an NVIDIA driver' in first
    assert second == "['ok']"


def test_cuda_on_a_machine_without_a_gpu_names_the_fix():
    from flatbody_env.integrators import cuda

    if cuda.is_available():
        pytest.skip("a CUDA target is present here")
    scene = load_scene("default")
    with pytest.raises(cuda.CudaUnavailableError, match=r'^device: .*pip install "flatbody\[gpu\]"'):
        simulate_batch(scene.body, [pack(scene.state)], times=[0.1], method="RK4", step=0.05, device="cuda")
