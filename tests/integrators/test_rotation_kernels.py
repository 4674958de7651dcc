"""The compiled two-polar methods carrying R (flatbody_env.integrators.rotation_kernels).

Oracles: scipy's DOP853 at 1e-13 on z = (y, vec(R)) (rhs_with_rotation), scipy.linalg.expm for the
exact rotation flows, and the compiled methods without R (the paper state must be bit for bit theirs).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from flatbody_env.integrators import Tolerances, get_method
from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
from flatbody_env.integrators.rotation_kernels import ENV_STEP_WITH_ROTATION
from flatbody_env.integrators.steppers import CompiledRotationEnvStep, make_env_step
from flatbody_env.physics.body import default_body
from flatbody_env.physics.equations import hat_paper, rhs_rotation_kernel, rotation_rate_kernel, turn_rotation_kernel

from tests.conftest import BODIES

Y0 = np.array([0.05, 0.02, 1.45, 1.77, 0.02, 0.0, 0.05, 1.4, 0.9, 1.0, 0.3])
U = np.array([0.1, -0.2, 0.05, 0.3])
PLAIN = {
    name: env_stepper(name).step_counted
    for name in ("DOP853-numba", "RK4", "splitting-strang", "splitting-suzuki4", "splitting-yoshida4")
}
# largest |R - R_ref| after 20 steps of dt = 0.05 with h = 0.01 (DOP853: rtol = atol = 1e-11): the
# method's order shows; Strang is second order
R_TOL = {
    "DOP853-numba": 1e-9,
    "RK4": 1e-7,
    "splitting-strang": 1e-4,
    "splitting-suzuki4": 1e-7,
    "splitting-yoshida4": 1e-6,
}


def _reference_R(body, y0, u, t_end, R0=None):
    R0 = np.eye(3) if R0 is None else R0
    sol = get_method("DOP853").integrate(
        body, y0, np.array([0.0, t_end]), tol=Tolerances(rtol=1e-13, atol=1e-13), u=u, R0=R0, with_rotation=True
    )
    return sol.Y[:, -1], sol.rotation[-1]


def test_rotation_kernels_are_the_physics_formulas():
    rng = np.random.default_rng(1)
    for _ in range(20):
        z = rng.normal(size=20)
        vel = rng.normal(size=7)
        out = np.zeros(20)
        rotation_rate_kernel(z, vel, out)
        assert np.allclose(out[11:].reshape(3, 3), z[11:].reshape(3, 3) @ hat_paper(vel[:3]), atol=1e-14)
        for axis in range(3):
            angle = rng.uniform(-3, 3)
            zz = z.copy()
            turn_rotation_kernel(zz, axis, angle)
            e = np.zeros(3)
            e[axis] = angle
            assert np.allclose(zz[11:].reshape(3, 3), z[11:].reshape(3, 3) @ expm(hat_paper(e)), atol=1e-13)
            assert np.array_equal(zz[:11], z[:11])
    # the 20-entry right-hand side: the paper rates are rhs_kernel's, R's are R W(omega)
    body = default_body()
    z = np.concatenate([Y0, np.eye(3).ravel()])
    out = np.empty(20)
    rhs_rotation_kernel(z, U, np.array(body.kernel_params()), out, np.empty(7), np.empty(4))
    from flatbody_env.physics.equations import rhs_with_rotation

    assert np.allclose(out, rhs_with_rotation(0.0, z, U, body), rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("name", sorted(ENV_STEP_WITH_ROTATION))
def test_env_step_with_R_keeps_the_paper_state_bit_for_bit_and_integrates_R(name):
    body = default_body()
    P = kernel_params(body)
    h = 0.05 if name == "DOP853-numba" else 0.01
    z = np.concatenate([Y0, np.eye(3).ravel()])
    y = Y0.copy()
    zo, yo = np.empty(20), np.empty(11)
    for _ in range(20):
        c1, c2 = np.zeros(3, np.int64), np.zeros(3, np.int64)
        assert ENV_STEP_WITH_ROTATION[name](z, U, P, 0.05, h, 1e-11, 1e-11, np.inf, zo, c1) == 0
        assert PLAIN[name](y, U, P, 0.05, h, 1e-11, 1e-11, np.inf, yo, c2) == 0
        assert np.array_equal(zo[:11], yo), "the paper state must not depend on carrying R"
        assert np.array_equal(c1, c2), "the same steps and evaluations"
        z, y = zo.copy(), yo.copy()
    y_ref, R_ref = _reference_R(body, Y0, U, 1.0)
    R = z[11:].reshape(3, 3)
    assert np.max(np.abs(R - R_ref)) < R_TOL[name]
    assert np.max(np.abs(R @ R.T - np.eye(3))) < max(1e-12, R_TOL[name])


@pytest.mark.parametrize("name", ["DOP853-numba", "RK4", "splitting-suzuki4"])
@pytest.mark.parametrize("body_name", ["V1", "V2", "V3"])
def test_integrate_with_rotation_compiled(name, body_name):
    body = BODIES[body_name]
    times = np.linspace(0.0, 10.0, 11)
    R0 = expm(hat_paper(np.array([0.3, -0.2, 0.5])))
    meth = get_method(name)
    tol = Tolerances(rtol=1e-11, atol=1e-11, step=None if meth.info.adaptive else 0.005)
    with_R = meth.integrate(body, Y0, times, tol=tol, R0=R0, with_rotation=True)
    without = meth.integrate(body, Y0, times, tol=tol)
    assert np.array_equal(with_R.Y, without.Y) and with_R.nfev == without.nfev
    ref = get_method("DOP853").integrate(
        body, Y0, times, tol=Tolerances(rtol=1e-13, atol=1e-13), R0=R0, with_rotation=True
    )
    assert with_R.rotation.shape == (11, 3, 3)
    assert np.allclose(with_R.rotation[0], R0, atol=0)
    err = np.max(np.abs(with_R.rotation - ref.rotation))
    assert err < (1e-8 if name == "DOP853-numba" else 1e-6), err
    # the laboratory spin R s is conserved without controls (docs/physics.md)
    lab = np.einsum("nij,jn->ni", with_R.rotation, with_R.Y[:3])
    assert np.max(np.abs(lab - lab[0])) < (1e-8 if name == "DOP853-numba" else 1e-6)


def test_make_env_step_carries_R_compiled():
    body = default_body()
    st = make_env_step("DOP853-numba", body, Tolerances(rtol=1e-11, atol=1e-11), with_rotation=True, first_step=0.05)
    assert isinstance(st, CompiledRotationEnvStep) and st.compiled and st.carries_rotation
    out, R_out, counters = np.empty(11), np.empty((3, 3)), np.zeros(3, np.int64)
    assert st.advance(Y0, U, 0.05, out, counters, np.eye(3), R_out) == 0
    y_ref, R_ref = _reference_R(body, Y0, U, 0.05)
    assert np.max(np.abs(R_out - R_ref)) < 1e-12 and np.max(np.abs(out - y_ref)) < 1e-12
    import pickle

    clone = pickle.loads(pickle.dumps(st))
    out2, R2 = np.empty(11), np.empty((3, 3))
    clone.advance(Y0, U, 0.05, out2, np.zeros(3, np.int64), np.eye(3), R2)
    assert np.array_equal(out2, out) and np.array_equal(R2, R_out)
