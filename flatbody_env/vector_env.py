"""``FlatBodyVectorEnv``: N bodies of ``FlatBody-v0`` advanced together, natively batched.

One call of the integrator's batch stepper (:func:`flatbody_env.integrators.make_batch_stepper`;
compiled methods advance all N bodies in one compiled call) per ``step``; rewards, observations
and domain checks are vectorised numpy. It truncates by itself after ``max_episode_steps`` and
autoresets in Gymnasium's default NEXT_STEP mode: the step after a body's episode ended resets
that body (its action is ignored, reward 0, terminated = truncated = False).

Sub-environment ``i`` reset with ``seed=s`` draws exactly what a single ``FlatBody-v0`` reset with
``seed=s + i`` draws, so N single environments and one vector environment produce the same
rollouts step for step (tested).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .conserved import casimir
from .env import FlatBodyEnv
from .hamiltonian import hamiltonian
from .integrators import make_batch_stepper
from .registration import MAX_EPISODE_STEPS
from .task import target_vector


class FlatBodyVectorEnv(VectorEnv):
    """N copies of :class:`~flatbody_env.env.FlatBodyEnv` in one batched simulation.

    Parameters
    ----------
    num_envs : int
        Number of bodies N.
    max_episode_steps : int
        Truncation horizon (400 = t 20 at dt 0.05, as registered).
    **kwargs
        The keyword arguments of :class:`~flatbody_env.env.FlatBodyEnv` (``render_mode`` and
        ``track_rotation`` are not supported here).

    Infos are dicts of arrays (Gymnasium's vector convention) with the keys of the single env:
    ``distance``, ``is_success``, ``energy``, ``casimir``, ``p_theta``, ``t``,
    ``integrator_failure`` (str, "" when none), ``left_domain`` and ``reward_terms`` (dict of arrays).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, max_episode_steps: int = MAX_EPISODE_STEPS, **kwargs: Any) -> None:
        if not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs: must be an integer >= 1, got {num_envs!r}")
        if not isinstance(max_episode_steps, int) or max_episode_steps < 1:
            raise ValueError(f"max_episode_steps: must be an integer >= 1, got {max_episode_steps!r}")
        if kwargs.get("render_mode") is not None or kwargs.get("track_rotation"):
            raise ValueError("render_mode: FlatBodyVectorEnv does not render; use FlatBody-v0 for frames")
        self._proto = FlatBodyEnv(**kwargs)
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_action_space = self._proto.action_space
        self.single_observation_space = self._proto.observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.body = self._proto.body
        self.task = self._proto.task
        self._batch = make_batch_stepper(self._proto.integrator, self.body, self._proto.tolerances)
        self._Y = np.zeros((num_envs, 11))
        self._targets: list[Any] = [None] * num_envs
        self._T = np.zeros((num_envs, 4))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]

    # --- helpers ---------------------------------------------------------------------------------------
    def _reset_one(self, i: int, options: dict[str, Any] | None) -> None:
        p = self._proto
        p._np_random = self._rngs[i]
        p.reset(options=options)
        self._rngs[i] = p.np_random
        self._Y[i] = p._y
        self._targets[i] = p._target
        self._T[i] = target_vector(p._target)
        self._steps[i] = 0

    def _observations(self) -> np.ndarray:
        Y = self._Y
        return np.concatenate([Y[:, :10], np.sin(Y[:, 10:11]), np.cos(Y[:, 10:11]), self._T], axis=1).astype(np.float32)

    def _infos(self, terms, failures, lefts) -> dict[str, Any]:
        Yt = self._Y.T
        distance = self.task.distance(Yt, self.body, self._T.T)
        bad = np.array([bool(f) or bool(l) for f, l in zip(failures, lefts)])
        info: dict[str, Any] = {
            "t": self._steps * self._proto.dt,
            "distance": distance,
            "is_success": (distance <= self.task.success_tolerance) & ~bad,
            "energy": np.array([hamiltonian(self._Y[i], self.body) for i in range(self.num_envs)]),
            "casimir": casimir(Yt[0], Yt[1], Yt[2]),
            "p_theta": Yt[3].copy(),
            "integrator_failure": np.array(failures, dtype=object),
            "left_domain": np.array(lefts, dtype=object),
        }
        if terms is not None:
            info["reward_terms"] = terms
        return info

    # --- VectorEnv API ------------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            seeds = list(seed) if isinstance(seed, (list, tuple)) else [seed + i for i in range(self.num_envs)]
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed: expected {self.num_envs} seeds, got {len(seeds)}")
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        for i in range(self.num_envs):
            self._reset_one(i, options)
        self._autoreset[:] = False
        blank = [""] * self.num_envs
        return self._observations(), self._infos(None, blank, blank)

    def step(self, actions):
        A = np.asarray(actions, dtype=np.float64).reshape((self.num_envs,) + self.single_action_space.shape)
        if not np.all(np.isfinite(A)):
            raise ValueError("actions: must be finite numbers in [-1, 1]")
        A = np.clip(A, -1.0, 1.0)
        p = self._proto
        mask = p._mask
        U = np.zeros((self.num_envs, 4))
        if mask.any():
            U[:, mask] = A * p.limits[mask]
        resetting = self._autoreset.copy()
        result = self._batch(self._Y, U, p.dt)
        failures = ["" if ok else reason for ok, reason in zip(result.ok, result.reasons)]
        lefts = [""] * self.num_envs
        for i in range(self.num_envs):
            if resetting[i]:
                continue
            if result.ok[i]:
                left = p._left_domain(result.Y[i])
                if left:
                    lefts[i] = left
                else:
                    self._Y[i] = result.Y[i]
        terminated = np.array([bool(failures[i] or lefts[i]) for i in range(self.num_envs)]) & ~resetting
        self._steps[~resetting] += 1
        truncated = (self._steps >= self.max_episode_steps) & ~terminated & ~resetting
        act = A if mask.any() else np.zeros_like(A)
        terms = self.task.reward_terms(self._Y.T, self.body, self._T.T, act, terminated)
        rewards = np.sum(np.stack(list(terms.values())), axis=0)
        for i in np.flatnonzero(resetting):
            self._reset_one(i, None)
            failures[i] = ""
            rewards[i] = 0.0
            for v in terms.values():
                v[i] = 0.0
        self._autoreset = terminated | truncated
        info = self._infos(terms, failures, lefts)
        return self._observations(), rewards, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        self._proto.close()


__all__ = ["FlatBodyVectorEnv"]
