"""Shared fixtures: bodies for every potential, random states, an independent Hamiltonian."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from flatbody_env.physics.body import Body, Inertia
from flatbody_env.physics.potentials import CustomPotential, ThicknessPotential, V1, V2, V3


def _custom() -> CustomPotential:
    # V = (λ² + μ²)/2 + 0.3 (λμ)⁻¹ + 0.2 λμϱ² (couples ϱ to the plane; symmetric in λ ↔ μ)
    return CustomPotential(
        value=lambda l, m, r: 0.5 * (l * l + m * m) + 0.3 / (l * m) + 0.2 * l * m * r * r,
        gradient=lambda l, m, r: (
            l - 0.3 / (l * l * m) + 0.2 * m * r * r,
            m - 0.3 / (l * m * m) + 0.2 * l * r * r,
            0.4 * l * m * r,
        ),
        label="test-custom",
    )


# Commands the tests start (rerun, dask, flatbody) come from the environment that runs the tests, as in
# an activated virtual environment: README's test command runs .venv/bin/python without activating it.
# The run folders the tests train are remembered as trusted in a configuration folder of the test
# session's own (agents.numpy_policy.remember_run), never in the user's ~/.config.
os.environ.setdefault("FLATBODY_CONFIG_HOME", tempfile.mkdtemp(prefix="flatbody-test-config-"))
_SCRIPTS = str(Path(sys.executable).parent)
if _SCRIPTS not in os.environ.get("PATH", "").split(os.pathsep):
    os.environ["PATH"] = _SCRIPTS + os.pathsep + os.environ.get("PATH", "")


BODIES = {
    "V1": Body(inertia=Inertia.isotropic(1.0, 0.7), potential=V1(k=1.3), thickness=ThicknessPotential(a=1.0, b=1.0)),
    "V2": Body(
        inertia=Inertia.isotropic(0.9, 1.1), potential=V2(c=0.8, d=1.2), thickness=ThicknessPotential(a=0.5, b=2.0)
    ),
    "V3": Body(
        inertia=Inertia.isotropic(1.0, 1.0), potential=V3(kappa=1.0), thickness=ThicknessPotential(a=1.0, b=1.0)
    ),
    "custom": Body(
        inertia=Inertia.isotropic(1.2, 0.8), potential=_custom(), thickness=ThicknessPotential(a=1.0, b=0.5)
    ),
    "V3-anisotropic": Body(
        inertia=Inertia(J1=1.3, J2=0.7, J3=0.5), potential=V3(kappa=0.9), thickness=ThicknessPotential(a=1.0, b=2.0)
    ),
    "V2-anisotropic": Body(
        inertia=Inertia(J1=0.6, J2=1.4, J3=1.0), potential=V2(c=1.0, d=0.5), thickness=ThicknessPotential(a=1.0, b=1.0)
    ),
}


@pytest.fixture(params=sorted(BODIES))
def body(request) -> Body:
    return BODIES[request.param]


def random_lanes(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """N generic states in structure-of-arrays layout, Y (11, N), and controls U (4, N): the lanes of the batched
    kernels' tests (each test then makes some lanes hard)."""
    rng = np.random.default_rng(seed)
    Y = np.empty((11, n))
    Y[0:3] = rng.uniform(-0.3, 0.3, (3, n))
    Y[2] += 1.2
    Y[3] = 1.8
    Y[4:7] = rng.uniform(-0.5, 0.5, (3, n))
    Y[7] = rng.uniform(1.2, 1.8, n)
    Y[8] = rng.uniform(0.6, 1.0, n)
    Y[9] = rng.uniform(0.8, 1.2, n)
    Y[10] = rng.uniform(-3, 3, n)
    U = rng.uniform(-0.5, 0.5, (4, n))
    return Y, U


def random_state(rng: np.random.Generator) -> np.ndarray:
    """A generic packed state away from λ = μ and the boundaries."""
    lam = rng.uniform(1.1, 2.0)
    mu = rng.uniform(0.4, 0.95)
    if rng.random() < 0.5:
        lam, mu = mu, lam
    return np.concatenate([rng.normal(size=7), [lam, mu, rng.uniform(0.5, 1.5), rng.uniform(-np.pi, np.pi)]])
