"""The compiled kernels equal the Python physics: RHS, potential invariants,
decomposition, environment steppers, caching, argument errors."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.integrators import IntegrationError, Tolerances, get_method
from flatbody_env.integrators.steppers import make_env_step
from flatbody_env.integrators import rattle_kernels as rk
from flatbody_env.integrators import twopolar_kernels as tk
from flatbody_env.integrators.compiled_methods import ENV_METHODS, env_stepper, kernel_params
from flatbody_env.integrators.failure import KINDS
from flatbody_env.physics.kinematics import decompose
from flatbody_env.physics.potentials import CustomPotential, ThicknessPotential, V1, V2, V3
from flatbody_env.physics.regular import regular_energy, regular_from_paper
from flatbody_env.scene import load_scene
from flatbody_env.physics.state import pack

BODIES = [
    Body(inertia=Inertia.isotropic(1.0, 1.0), potential=V3(kappa=1.0), thickness=ThicknessPotential(a=1.0, b=1.0)),
    Body(inertia=Inertia.isotropic(1.3, 0.7), potential=V1(k=2.0), thickness=ThicknessPotential(a=0.5, b=2.0)),
    Body(
        inertia=Inertia(J1=1.2, J2=0.8, J3=1.0), potential=V2(c=0.7, d=1.1), thickness=ThicknessPotential(a=1.0, b=1.0)
    ),
    Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=V3(kappa=1.0),
        thickness=ThicknessPotential(a=1.0, b=1.0),
        spin_convention="paper",
    ),
]


def _random_state(rng):
    y = rng.normal(size=11)
    y[7:10] = rng.uniform(0.5, 1.8, size=3)
    y[10] = rng.uniform(-3, 3)
    return y


@pytest.mark.parametrize("body", BODIES, ids=["V3", "V1", "aniso-V2", "paper-convention"])
def test_compiled_rhs_equals_python_rhs(body):
    rng = np.random.default_rng(1)
    P = kernel_params(body)
    for _ in range(20):
        y = _random_state(rng)
        u = rng.normal(size=4)
        out = np.empty(11)
        tk.rhs_compiled(y, u, P, out)
        ref = rhs(0.0, y, u, body)
        assert np.allclose(out, ref, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("pot", [V1(k=1.7), V2(c=0.9, d=0.9), V3(kappa=1.3)], ids=["V1", "V2", "V3"])
def test_invariant_gradient_kernel_equals_physics(pot):
    rng = np.random.default_rng(2)
    c1 = pot.constants[0]
    for _ in range(10):
        tr, det = rng.uniform(1.0, 4.0), rng.uniform(0.2, 1.0)
        assert np.allclose(
            rk.invariant_gradient_kernel(float(pot.kind), c1, tr, det), pot.invariant_gradient(tr, det), rtol=1e-14
        )


def test_regular_energy_and_forces_equal_python():
    body = BODIES[0]
    rng = np.random.default_rng(3)
    P = kernel_params(body)
    for _ in range(10):
        y = _random_state(rng)
        y[0:7] *= 0.3
        z = regular_from_paper(y, body)
        assert rk.regular_energy_kernel(z, P) == pytest.approx(regular_energy(z, body), rel=1e-13)
        assert rk.regular_energy_kernel(z, P) == pytest.approx(hamiltonian(y, body), rel=1e-12)
        # forces are minus the gradient of V: central differences of the energy at rest
        F = np.empty(9)
        rk.forces(z[:9], P, 0.0, F)
        zz = np.concatenate([z[:9], np.zeros(9)])
        for i in (0, 4, 8):
            e = np.zeros(18)
            e[i] = 1e-6
            g = (rk.regular_energy_kernel(zz + e, P) - rk.regular_energy_kernel(zz - e, P)) / 2e-6
            assert F[i] == pytest.approx(-g, rel=1e-6, abs=1e-8)


def test_decompose_kernel_equals_kinematics_decompose():
    body = BODIES[0]
    rng = np.random.default_rng(4)
    for _ in range(10):
        y = _random_state(rng)
        z = regular_from_paper(y, body)
        ref = decompose(z[:9].reshape(3, 3).T)
        refvec = np.concatenate([ref.R.ravel(), [ref.lam, ref.mu, ref.rho, ref.theta]])
        out = np.empty(13)
        jump = rk.decompose_kernel(z[:9].copy(), refvec, False, out)
        assert jump < 1e-12
        assert np.allclose(out, refvec, atol=1e-12)


@pytest.mark.parametrize("name", ENV_METHODS)
def test_env_step_equals_integrate_and_batch_equals_single(name):
    sc = load_scene("default")
    body = sc.body
    y = pack(sc.state)
    P = kernel_params(body)
    st = env_stepper(name)
    meth = get_method(name)
    tol = Tolerances(rtol=1e-9, atol=1e-9, step=None if meth.info.adaptive else 0.01)
    u = np.zeros(4)
    x = y
    out = np.empty_like(x)
    status = st.step(x, u, P, 0.05, tol.step or 0.0, tol.rtol, tol.atol, np.inf, out)
    assert status == 0
    ref = meth.integrate(body, y, np.array([0.0, 0.05]), tol=tol).Y[:, -1]
    assert np.allclose(out, ref, rtol=0, atol=1e-14)
    X = np.stack([x, x, x], axis=1).copy()
    U = np.zeros((4, 3))
    U[3, 1] = 0.5  # a different control on body 1
    OUT = np.empty_like(X)
    STATUS = np.full(3, -1, np.int64)
    st.batch(X, U, P, 0.05, tol.step or 0.0, tol.rtol, tol.atol, np.inf, OUT, STATUS)
    assert list(STATUS) == [0, 0, 0]
    assert np.array_equal(OUT[:, 0], out) and np.array_equal(OUT[:, 2], out)
    assert not np.allclose(OUT[:, 1], out)


def test_seam_uses_the_compiled_stepper_and_flags_failures():
    sc = load_scene("close-approach").with_state(s3=1.0 + 5e-7, p_theta=1.0 - 5e-7)
    y = pack(sc.state)
    stepper = make_env_step("RK4", sc.body, Tolerances(step=0.05))
    assert type(stepper).__name__ == "CompiledEnvStep" and stepper.compiled
    kinds = set()
    out, OUT = np.empty(11), np.empty((11, 1))
    STATUS, NFEV = np.zeros(1, np.int64), np.zeros(1, np.int64)
    for _ in range(400):
        st = stepper.advance(y, np.zeros(4), 0.05, out, np.zeros(3, np.int64))
        stepper.advance_batch(y[:, None].copy(), np.zeros((4, 1)), 0.05, OUT, STATUS, NFEV)
        assert st == STATUS[0]
        if st:
            kinds.add(stepper.describe(st).split(":")[0])
            break
        y = out.copy()
    assert kinds & {"chart-singularity", "under-resolved", "non-finite", "energy"}, (
        "RK4 crossed the close pass unflagged"
    )


def test_compiled_methods_refuse_custom_potentials_and_missing_steps():
    body = Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=CustomPotential(value=lambda l, m, r: 0.5 * (l * l + m * m), gradient=lambda l, m, r: (l, m, 0.0)),
        thickness=ThicknessPotential(a=1.0, b=1.0),
    )
    y = pack(load_scene("default").state)
    for name in ("DOP853-numba", "RK4", "RATTLE-suzuki4"):
        with pytest.raises(ValueError, match="potential"):
            get_method(name).integrate(
                body, y, np.array([0.0, 1.0]), tol=Tolerances(step=None if name == "DOP853-numba" else 0.1)
            )
    good = load_scene("default").body
    with pytest.raises(ValueError, match="step"):
        get_method("RK4").integrate(good, y, np.array([0.0, 1.0]), tol=Tolerances())
    with pytest.raises(ValueError, match="step"):
        get_method("DOP853-numba").integrate(good, y, np.array([0.0, 1.0]), tol=Tolerances(step=0.1))
    with pytest.raises(ValueError, match="J1 = J2"):
        get_method("splitting-strang").integrate(BODIES[2], y, np.array([0.0, 1.0]), tol=Tolerances(step=0.1))


def test_simulate_and_cli_accept_every_compiled_method(capsys):
    from flatbody_env.cli.main import main
    from flatbody_env.simulation import simulate

    for name in (
        "DOP853-numba",
        "RK4",
        "splitting-strang",
        "splitting-suzuki4",
        "splitting-yoshida4",
        "RATTLE",
        "RATTLE-suzuki4",
    ):
        step = None if name == "DOP853-numba" else 0.01
        traj = simulate("regular", t_end=2.0, method=name, step=step)
        assert traj.method == name and np.all(np.isfinite(traj.y))
        args = ["simulate", "--scene", "regular", "--t-end", "1", "--method", name, "--summary"]
        if step:
            args += ["--step", "0.01"]
        assert main(args) == 0
    with pytest.raises(ValueError, match="step"):
        simulate("regular", t_end=1.0, method="RK4")
    assert main(["simulate", "--scene", "regular", "--method", "RK4"]) == 2
    assert "step" in capsys.readouterr().err


def test_failure_kinds_are_named():
    assert KINDS[0] == "ok" and len(set(KINDS)) == len(KINDS)
    with pytest.raises(IntegrationError) as info:
        from flatbody_env.integrators.failure import raise_for

        raise_for(3, t=1.5, method="RK4")
    assert info.value.kind == "chart-singularity" and info.value.t == 1.5
