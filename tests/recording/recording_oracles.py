"""Shared fixtures and independent oracles of the recording tests.

G and C are recomputed here from scratch — Φ = R D U(θ)⁻¹ (eqs. (23)–(24) of the paper), G = ΦᵀΦ
(eq. (33)), C = (ΦΦᵀ)⁻¹ (the corrected eq. (51) remark, docs/physics.md) — not with kinematics.py.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import rerun as rr

from flatbody_env import load_scene, simulate
from flatbody_env.recording.reader import read_recording
from flatbody_env.recording.writer import record_trajectory

N = 201
T_END = 5.0
SCALARS = "Scalars:scalars"


@pytest.fixture(autouse=True)
def strict_rerun():
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(False)


@pytest.fixture(scope="module")
def scene():
    return load_scene("default")


@pytest.fixture(scope="module")
def traj(scene):
    tr = simulate(scene, t_end=T_END, times=np.linspace(0.0, T_END, N), with_rotation=True)
    assert np.abs(tr.rotation[-1] - np.eye(3)).max() > 0.5, "the scene must rotate for the test to mean anything"
    assert abs(tr.state["theta"][-1] - tr.state["theta"][0]) > 1.0
    return tr


@pytest.fixture(scope="module")
def recorded(traj, scene, tmp_path_factory):
    rr.set_strict_mode(True)
    path = tmp_path_factory.mktemp("rec") / "run.rrd"
    out = record_trajectory(traj, scene.body, path, tensor_every=10)
    assert out == path
    return path, read_recording(path)


def series(data, name):
    return np.asarray(data[f"/series/{name}"].components[SCALARS])[:, 0]


def record_flatbody_episode(path, *, seed: int, steps: int, **wrapper_kwargs) -> None:
    """One FlatBody-v0 episode of ``steps`` seeded random actions recorded to ``path`` by ``RerunRecorder``."""
    import flatbody_env  # noqa: F401  (registers FlatBody-v0)
    from flatbody_env.recording.wrapper import RerunRecorder

    env = RerunRecorder(gym.make("FlatBody-v0", track_rotation=True, max_episode_steps=steps), path, **wrapper_kwargs)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
        done = term or trunc
    env.close()


def material_U(theta):
    c, s = np.cos(theta), np.sin(theta)
    U = np.zeros(theta.shape + (3, 3))
    U[:, 0, 0], U[:, 0, 1], U[:, 1, 0], U[:, 1, 1], U[:, 2, 2] = c, -s, s, c, 1.0
    return U


def phi_of(lam, mu, rho, theta, R):
    D = np.zeros(lam.shape + (3, 3))
    D[:, 0, 0], D[:, 1, 1], D[:, 2, 2] = lam, mu, rho
    return R @ D @ np.swapaxes(material_U(theta), 1, 2)


class FakeFlatBodyEnv(gym.Env):
    """Meets the RerunRecorder contract; states from flatbody_env.simulate (actions ignored)."""

    metadata = {"render_modes": []}

    def __init__(self, n_steps: int = 23, dt: float = 0.05, fail_at: int | None = None, track_rotation: bool = True):
        sc = load_scene("default")
        self.body = sc.body
        self.n_steps = n_steps
        self.fail_at = fail_at
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (11,), np.float64)
        self._traj = simulate(
            sc, t_end=n_steps * dt, times=np.linspace(0.0, n_steps * dt, n_steps + 1), with_rotation=True
        )
        self.target = {"lambda": 1.2, "mu": 1.0, "rho": 1.0, "s3": 0.5, "label": "circle"}
        self._k = 0

    @property
    def state(self):
        st = {k: float(v[self._k]) for k, v in self._traj.state.items()}
        if self.fail_at is not None and self._k >= self.fail_at:
            st["lambda"] = float("nan")
        return st

    @property
    def rotation(self):
        return self._traj.rotation[self._k].copy()

    @property
    def time(self):
        return float(self._traj.t[self._k])

    def _obs(self):
        return self._traj.y[:, self._k].copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._k = 0
        return self._obs(), {}

    def step(self, action):
        self._k += 1
        a = np.asarray(action, float)
        terms = {"shape": -abs(self._traj.state["lambda"][self._k] - 1.2), "effort": -0.01 * float(a @ a)}
        terminated = self._k == self.n_steps
        return self._obs(), sum(terms.values()), terminated, False, {"reward_terms": terms}
