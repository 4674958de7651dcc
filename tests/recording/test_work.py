"""The energy balance of a controlled episode: H(t) − H(0) = W(t) = ∫ P dt with P = ω·τ + ϱ̇ f_ϱ.

The oracle is independent of :mod:`flatbody_env.recording.work`: every env step is re-integrated with
scipy's DOP853 at rtol 1e-12 from the env's state under the step's controls, and the power along that
dense solution is integrated with 12-point Gauss–Legendre, with ω and ϱ̇ from the scalar Legendre map
(:func:`velocities_from_momenta`).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import flatbody_env  # noqa: F401  (registers FlatBody-v0)
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.hamiltonian import hamiltonian_series, velocities_from_momenta
from flatbody_env.recording.reader import read_recording
from flatbody_env.recording.work import control_power, step_work
from flatbody_env.recording.wrapper import RerunRecorder

STEPS = 60


def _power(y, u, body):
    v = velocities_from_momenta(y, body)
    return v["omega1"] * u[0] + v["omega2"] * u[1] + v["omega3"] * u[2] + v["rho_dot"] * u[3]


@pytest.fixture(scope="module")
def controlled(tmp_path_factory):
    """A torque+dilatation episode with strong random actions, recorded, and its states and controls."""
    path = tmp_path_factory.mktemp("work") / "ep.rrd"
    env = RerunRecorder(gym.make("FlatBody-v0", track_rotation=True, max_episode_steps=STEPS), path)
    env.reset(seed=11)
    u = env.unwrapped
    rng = np.random.default_rng(11)
    t, Y, U = [u.time], [u.physics_state.copy()], []
    done = False
    while not done:
        a = rng.uniform(-1, 1, 4)
        U.append(u.controls(a)[1])
        _, _, term, trunc, _ = env.step(a)
        t.append(u.time)
        Y.append(u.physics_state.copy())
        done = term or trunc
    env.close()
    return path, np.array(t), np.stack(Y, axis=1), np.array(U), u.body


def test_energy_change_equals_the_work_of_the_controls(controlled):
    path, t, Y, U, body = controlled
    H = hamiltonian_series(Y, body)
    assert np.ptp(H) > 0.05  # the controls change H by a visible amount: the check is not vacuous
    nodes, weights = np.polynomial.legendre.leggauss(12)
    W = [0.0]
    for k in range(1, t.size):
        sol = solve_ivp(
            lambda s, y, k=k: rhs(s, y, U[k - 1], body),
            (t[k - 1], t[k]),
            Y[:, k - 1],
            method="DOP853",
            rtol=1e-12,
            atol=1e-12,
            dense_output=True,
        )
        h = t[k] - t[k - 1]
        s = t[k - 1] + 0.5 * h * (nodes + 1.0)
        W.append(W[-1] + 0.5 * h * sum(w * _power(sol.sol(x), U[k - 1], body) for x, w in zip(s, weights)))
    W = np.array(W)
    # the env's integrator (DOP853-numba, rtol = atol = 1e-11) against the fine quadrature
    np.testing.assert_allclose(H - H[0], W, atol=1e-8 * max(1.0, np.abs(H).max()))
    # the recording's work (corrected trapezoid from the step ends) equals both, to the same tolerance
    data = read_recording(path)
    W_rec = data["/series/balance/work"].components["Scalars:scalars"][:, 0]
    dH_rec = data["/series/balance/delta_energy"].components["Scalars:scalars"][:, 0]
    np.testing.assert_allclose(dH_rec, H - H[0], atol=1e-12)
    np.testing.assert_allclose(W_rec, W, atol=1e-6 * max(1.0, np.abs(H).max()))
    # the power panel: the mean power of each step times its length is the step's work
    P = data["/series/power"].components["Scalars:scalars"][:, 0]
    np.testing.assert_allclose(P * np.diff(t), np.diff(W), atol=1e-6)


def test_power_is_omega_dot_tau_plus_rho_dot_f(controlled):
    _, _, Y, U, body = controlled
    P = control_power(Y[:, 1:], U, body)
    ref = [_power(Y[:, k + 1], U[k], body) for k in range(U.shape[0])]
    np.testing.assert_allclose(P, ref, rtol=1e-12, atol=1e-14)
    # no control, no work
    assert np.all(step_work(np.zeros(3), Y[:, :3], np.full(3, 0.05), Y[:, 1:4], np.zeros((3, 4)), body) == 0.0)
