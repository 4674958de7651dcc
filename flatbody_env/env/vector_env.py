"""``FlatBodyVectorEnv``: N bodies of ``FlatBody-v0`` advanced together, natively batched.

With a compiled integrator (the default) a ``step`` is two compiled calls: the method's batch
stepper advances all N bodies (structure-of-arrays), then
:func:`flatbody_env.env.kernels.post_step_batch` checks the domain, observes and scores all N.
Other integrators go through :func:`flatbody_env.integrators.make_batch_stepper` (a loop). It truncates by itself after ``max_episode_steps`` and
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

from flatbody_env.env import kernels as env_kernels
from flatbody_env.env.env import FlatBodyEnv
from flatbody_env.integrators import make_batch_stepper
from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.env.task import REWARD_TERMS, target_vector


class FlatBodyVectorEnv(VectorEnv):
    """N copies of :class:`~flatbody_env.env.env.FlatBodyEnv` in one batched simulation.

    Parameters
    ----------
    num_envs : int
        Number of bodies N.
    max_episode_steps : int
        Truncation horizon (400 = t 20 at dt 0.05, as registered).
    **kwargs
        The keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (``render_mode`` and
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
        p = self._proto
        self._fast = p._fast
        if self._fast is None:
            self._batch = make_batch_stepper(p.integrator, self.body, p.tolerances)
            self._post_batch = env_kernels.post_step_batch
        else:
            self._post_batch = self._fast.kernels.post_step_batch
        n_act = p._a.size
        self._Ys = np.zeros((11, num_envs))
        self._OUT = np.zeros((11, num_envs))
        self._Ynext = np.zeros((11, num_envs))
        self._U = np.zeros((4, num_envs))
        self._STATUS = np.zeros(num_envs, dtype=np.int64)
        self._A = np.zeros((num_envs, n_act))
        self._OBS = np.zeros((num_envs, 16), dtype=np.float32)
        self._TERMS = np.zeros((6, num_envs))
        self._SC = np.zeros((4, num_envs))
        self._ENDED = np.zeros(num_envs, dtype=np.int64)
        self._work = (np.empty(7), np.empty(4))
        self._targets: list[Any] = [None] * num_envs
        self._T = np.zeros((num_envs, 4))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]

    @property
    def _Y(self) -> np.ndarray:
        """States as (N, 11) (a view of the structure-of-arrays storage)."""
        return self._Ys.T

    # --- helpers ---------------------------------------------------------------------------------------
    def _reset_one(self, i: int, options: dict[str, Any] | None):
        """Reset body i exactly as a single env would; returns that env's (obs, info)."""
        p = self._proto
        p._np_random = self._rngs[i]
        obs, info = p.reset(options=options)
        self._rngs[i] = p.np_random
        self._Ys[:, i] = p._y
        self._targets[i] = p._target
        self._T[i] = target_vector(p._target)
        self._steps[i] = 0
        return obs, info

    def _infos(self, terms, sc, failures, lefts, ended) -> dict[str, Any]:
        info: dict[str, Any] = {
            "t": self._steps * self._proto.dt,
            "distance": sc[0].copy(),
            "is_success": (sc[0] <= self.task.success_tolerance) & ~ended,
            "energy": sc[1].copy(),
            "casimir": sc[2].copy(),
            "p_theta": self._Ys[3].copy(),
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
        obs = np.empty((self.num_envs, 16), dtype=np.float32)
        sc = np.zeros((4, self.num_envs))
        for i in range(self.num_envs):
            obs[i], info = self._reset_one(i, options)
            sc[0, i], sc[1, i], sc[2, i] = info["distance"], info["energy"], info["casimir"]
        self._autoreset[:] = False
        blank = [""] * self.num_envs
        return obs, self._infos(None, sc, blank, blank, np.zeros(self.num_envs, dtype=bool))

    def step(self, actions):
        A = np.asarray(actions, dtype=np.float64).reshape((self.num_envs,) + self.single_action_space.shape)
        if not np.all(np.isfinite(A)):
            raise ValueError("actions: must be finite numbers in [-1, 1]")
        p = self._proto
        mask = p._mask
        np.clip(A, -1.0, 1.0, out=self._A)
        if mask.any():
            self._U[mask] = self._A.T * p.limits[mask, None]
        else:
            self._A[:] = 0.0
        resetting = self._autoreset.copy()
        if self._fast is not None:
            tol = p.tolerances
            self._fast.stepper.batch(self._Ys, self._U, p._P, p.dt, p._h_guess, tol.rtol, tol.atol, np.inf, self._OUT, self._STATUS)
            status = self._STATUS
        else:
            result = self._batch(self._Ys.T, self._U.T, p.dt)
            self._OUT[:] = result.Y.T
            status = (~result.ok).astype(np.int64)
        self._post_batch(self._Ys, self._OUT, status, self._A, self._A.shape[1], self._T, p._cfg, p._P,
                         self._Ynext, self._OBS, self._TERMS, self._SC, self._ENDED, *self._work)
        ended = self._ENDED.astype(bool) & ~resetting
        failures = [""] * self.num_envs
        lefts = [""] * self.num_envs
        for i in np.flatnonzero(ended):
            if status[i] != 0:
                failures[i] = result.reasons[i] if self._fast is None else f"{self._fast.kinds[status[i]]}: {self._fast.reason(status[i])}"
            else:
                lefts[i] = p._left_domain(self._OUT[:, i]) or ""
        keep = ~resetting
        self._Ys[:, keep] = self._Ynext[:, keep]
        self._steps[keep] += 1
        terminated = ended
        truncated = (self._steps >= self.max_episode_steps) & ~terminated & keep
        obs = self._OBS.copy()
        rewards = self._TERMS.sum(axis=0)
        terms = dict(zip(REWARD_TERMS, self._TERMS.copy()))
        sc = self._SC.copy()
        for i in np.flatnonzero(resetting):
            rewards[i] = 0.0
            for v in terms.values():
                v[i] = 0.0
            obs[i], info = self._reset_one(i, None)
            sc[0, i], sc[1, i], sc[2, i] = info["distance"], info["energy"], info["casimir"]
        self._autoreset = terminated | truncated
        return obs, rewards, terminated, truncated, self._infos(terms, sc, failures, lefts, ended)

    def close_extras(self, **kwargs: Any) -> None:
        self._proto.close()


__all__ = ["FlatBodyVectorEnv"]
