"""A body with a custom (Python) potential in the environments: it resets (the settling-rate table is
for the built-in body only) and ``info["energy"]`` is the whole H, the custom in-plane part included
(the compiled bookkeeping knows the built-in potentials only; the envs add the rest)."""

from __future__ import annotations

import dataclasses

import numpy as np

from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.env.vector_env import FlatBodyVectorEnv
from flatbody_env.physics.body import default_body
from flatbody_env.physics.hamiltonian import hamiltonian
from flatbody_env.physics.potentials import CustomPotential


def _v3_as_custom():
    """The default body's V3 (κ = 1, eq. (39)) written as a custom potential."""
    body = default_body()
    kappa = body.potential.kappa

    def value(lam, mu, rho):
        return kappa * (1.0 / (lam * mu) + 0.5 * (lam * lam + mu * mu))

    def gradient(lam, mu, rho):
        return kappa * (lam - 1.0 / (lam * lam * mu)), kappa * (mu - 1.0 / (lam * mu * mu)), 0.0

    return dataclasses.replace(body, potential=CustomPotential(value=value, gradient=gradient, label="V3 by hand"))


def test_single_env_with_a_custom_potential_reports_the_whole_energy():
    body = _v3_as_custom()
    env = FlatBodyEnv(body=body, integrator="DOP853")
    twin = FlatBodyEnv(integrator="DOP853")  # the same body with the built-in V3
    _, info = env.reset(seed=3)
    np.array(list(env.state.values()))
    assert abs(info["energy"] - hamiltonian(env.state, body)) < 1e-12
    _, twin_info = twin.reset(seed=3, options={"state": env.state})  # (the energy does not depend on the target)
    assert abs(info["energy"] - twin_info["energy"]) < 1e-12 * abs(twin_info["energy"])
    zero = np.zeros(env.action_space.shape)
    energies = [env.step(zero)[4]["energy"] for _ in range(20)]
    assert abs(energies[-1] - hamiltonian(env.state, body)) < 1e-12
    assert max(abs(e - info["energy"]) for e in energies) < 1e-8  # no control: H is conserved


def test_vector_env_with_a_custom_potential_reports_the_whole_energy():
    body = _v3_as_custom()
    venv = FlatBodyVectorEnv(3, body=body, integrator="DOP853")
    _, info = venv.reset(seed=5)
    for k, y in enumerate(venv.states):
        assert abs(info["energy"][k] - hamiltonian(y, body)) < 1e-12
    _, _, _, _, info = venv.step(np.zeros((3,) + venv.single_action_space.shape))
    for k, y in enumerate(venv.states):
        assert abs(info["energy"][k] - hamiltonian(y, body)) < 1e-12
