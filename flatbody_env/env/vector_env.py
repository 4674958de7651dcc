"""``FlatBodyVectorEnv``: N bodies of ``FlatBody-v0`` advanced together, natively batched.

A ``step`` is the single env's step path for N bodies at once: the actions are clipped and scaled
by :func:`flatbody_env.env.kernels.controls_batch`, the seam's stepper
(:func:`flatbody_env.integrators.steppers.make_env_step`) advances all N bodies in one call
(structure-of-arrays; compiled where the method has a compiled environment stepper), the
bookkeeping :func:`flatbody_env.env.kernels.post_step_lanes` checks the domain, observes and scores
all N, and :func:`flatbody_env.env.env.build_info` builds the infos. It uses the single env only
through its public API (:meth:`~flatbody_env.env.env.FlatBodyEnv.draw_episodes`, ``use_body``,
:meth:`~flatbody_env.env.env.FlatBodyEnv.observe`, ``sampler``, ``stepper``, ``kernels``, ``kernel_params``,
``kernel_config``, ``left_domain``).

Batches can be split across threads (``num_threads``; None: one per available core, at least
:data:`LANES_PER_THREAD` bodies each; default 1): the compiled stepper and bookkeeping release the
GIL, each thread advances and scores its own slice of bodies with its own work arrays, and the result
does not depend on the split (each body's arithmetic is its own; tested). One thread is the default:
more threads gained little with the cores free and lost with another process busy (measured by
``flatbody bench env``, its 2-thread row; docs/env.md, "Batched" and "Benchmark").

It truncates by itself after ``max_episode_steps`` and autoresets in Gymnasium's default
NEXT_STEP mode (the step after a body's episode ended resets that body: its action is ignored,
reward 0, terminated = truncated = False), or in SAME_STEP mode (``autoreset_mode``): a body whose
episode ends is reset within the same step, its last observation in ``info["final_obs"]`` (rows
flagged by ``info["_final_obs"]``).

Episode clocks and partial resets (Isaac Lab's episode-length randomisation): ``reset(options={"stagger": True})``
starts every body's clock at a uniform random step in [0, ``max_episode_steps``) (drawn from a generator of
its own, seeded from ``seed``: the bodies' episode draws are unchanged), so that the first truncations are
spread over an episode's length instead of all falling on one step; :attr:`~FlatBodyVectorEnv.episode_steps`
reads the clocks and :meth:`~FlatBodyVectorEnv.set_episode_steps` sets them. ``reset(options={"reset_mask": m})``
(Gymnasium's convention) resets only the bodies where the bool mask ``m`` (N,) is set (re-seeded with
``seed + i`` when ``seed`` is given); the others keep their state, clock and observation, which the returned
observation carries in their rows.

Sub-environment ``i`` reset with ``seed=s`` draws exactly what a single ``FlatBody-v0`` reset with
``seed=s + i`` draws, so N single environments and one vector environment produce the same
rollouts step for step (tested, for every registered task). A task's draws run through the episode
sampler's kernels where they can (``FlatBody-v0``, ``FlatBodySlow-v0``, ``FlatBodyHoldUnstable-v0``),
else through the task's batch draw (:meth:`~flatbody_env.env.env.FlatBodyEnv.draw_episodes`: the
witnessed starts of ``FlatBodyTorque-v0`` simulate all resetting bodies as one batch). A task's own
termination and reward terms are applied after the bookkeeping, as in the single env. A task that
draws a body per episode (``FlatBodyAnyBody-v0``) steps each body with its own stepper and kernel
parameters, one body after another (the single env's step, body by body; one thread).
"""

from __future__ import annotations

import copy
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from flatbody_env.env.env import FlatBodyEnv, build_info
from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.env.task import OBSERVATION_SIZE, Episode
from flatbody_env.physics.state import STATE_SIZE


LANES_PER_THREAD = 256
"""Fewest bodies per thread of the automatic split (below that a thread costs more than it saves)."""
MAX_THREADS = 64
"""Largest ``num_threads`` accepted."""


def available_cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def batch_arguments(num_envs, max_episode_steps, autoreset_mode) -> tuple[int, int, AutoresetMode]:
    """The batch's size, episode length and autoreset mode, checked before any allocation (shared by
    :class:`FlatBodyVectorEnv` and the torch vector env). ValueError naming the argument and its range."""
    from flatbody_env.physics import validation

    num_envs = validation.count("num_envs", num_envs, high=validation.MAX_BATCH)
    max_episode_steps = validation.count("max_episode_steps", max_episode_steps, high=validation.MAX_EPISODE_STEPS)
    try:
        mode = AutoresetMode(autoreset_mode)
    except ValueError:
        raise ValueError(f"autoreset_mode: must be NextStep or SameStep, got {autoreset_mode!r}") from None
    if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        raise ValueError(f"autoreset_mode: must be NextStep or SameStep, got {autoreset_mode!r}")
    return num_envs, max_episode_steps, mode


class FlatBodyVectorEnv(VectorEnv):
    """N copies of :class:`~flatbody_env.env.env.FlatBodyEnv` in one batched simulation.

    Parameters
    ----------
    num_envs : int
        Number of bodies N.
    max_episode_steps : int
        Truncation horizon (400 = t 20 at dt 0.05, as registered).
    autoreset_mode : AutoresetMode
        ``NEXT_STEP`` (default, Gymnasium's default) or ``SAME_STEP`` (module docstring).
    num_threads : int or None
        Threads that step the bodies (1 ... :data:`MAX_THREADS`; default 1); None: one per available
        core, at most one per :data:`LANES_PER_THREAD` bodies. Always 1 when the integrator does not run compiled.
    **kwargs
        The keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (``render_mode`` and
        ``track_rotation`` are not supported here).

    Infos are dicts of arrays (Gymnasium's vector convention) with the keys of the single env
    (:func:`~flatbody_env.env.env.build_info`): ``distance``, ``is_success``, ``energy``, ``casimir``,
    ``p_theta``, ``t``, ``integrator`` ({"method", "nfev" (N,)}), ``integrator_failure`` (str, ""
    when none), ``left_domain`` and ``reward_terms`` (dict of arrays).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int = MAX_EPISODE_STEPS,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int | None = 1,
        **kwargs: Any,
    ) -> None:
        num_envs, max_episode_steps, mode = batch_arguments(num_envs, max_episode_steps, autoreset_mode)
        if num_threads is not None and (
            not isinstance(num_threads, int) or isinstance(num_threads, bool) or not 1 <= num_threads <= MAX_THREADS
        ):
            raise ValueError(f"num_threads: must be an integer in [1, {MAX_THREADS}] or None, got {num_threads!r}")
        if kwargs.get("render_mode") is not None or kwargs.get("track_rotation"):
            raise ValueError("render_mode: FlatBodyVectorEnv does not render; use FlatBody-v0 for frames")
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.single_env = FlatBodyEnv(**kwargs)
        """The single environment whose configuration all N bodies share (its own state is unused)."""
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.single_action_space = self.single_env.action_space
        self.single_observation_space = self.single_env.observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        p = self.single_env
        self.body = p.body
        self.task = p.task
        self.control = p.control
        self.limits = p.limits
        self.dt = p.dt
        self.stepper = p.stepper
        self._kernels = p.kernels
        n_act = self.single_action_space.shape[0]
        self.reward_names = p.reward_names
        """The names of ``info["reward_terms"]`` (the task's)."""
        n_terms = len(self.reward_names)
        self._own_terms = bool(self.task.extra_reward_names)
        self._bodies = [p.body] * num_envs if self.task.varies_body else None
        self._lane_steppers = [self.stepper] * num_envs if self.task.varies_body else None
        self._lane_P = np.tile(p.kernel_params[:, None], (1, num_envs)) if self.task.varies_body else None
        self._witnesses: list[np.ndarray | None] = [None] * num_envs
        self._Ys = np.zeros((STATE_SIZE, num_envs))
        self._OUT = np.zeros((STATE_SIZE, num_envs))
        self._Ynext = np.zeros((STATE_SIZE, num_envs))
        self._U = np.zeros((4, num_envs))
        self._STATUS = np.zeros(num_envs, dtype=np.int64)
        self._NFEV = np.zeros(num_envs, dtype=np.int64)
        self._A = np.zeros((num_envs, n_act))
        self._OBS = np.zeros((num_envs, p.observation_size), dtype=np.float32)
        self._OBS_EXTRA = np.tile(self.task.observation_extra(p.body).astype(np.float32), (num_envs, 1))
        self._TERMS = np.zeros((n_terms, num_envs))
        self._SC = np.zeros((4, num_envs))
        self._ENDED = np.zeros(num_envs, dtype=np.int64)
        self._T = np.zeros((num_envs, 4))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._cur_obs = np.zeros((num_envs, p.observation_size), dtype=np.float32)  # every body's current observation
        self._cur_sc = np.zeros((4, num_envs))  # and its scalars (distance, energy, casimir, code)
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._blank = np.full(num_envs, "", dtype=object)
        self._mask_u8 = self.single_env.mask.astype(np.uint8)
        if not self.stepper.compiled or self.task.varies_body:
            threads = 1
        elif num_threads is None:
            threads = max(1, min(available_cores(), num_envs // LANES_PER_THREAD))
        else:
            threads = min(num_threads, num_envs)
        self.num_threads = threads
        """Threads that step the bodies (1: the calling thread alone)."""
        edges = np.linspace(0, num_envs, threads + 1).round().astype(int)
        self._slices = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
        self._steppers = [self.stepper] + [copy.deepcopy(self.stepper) for _ in range(threads - 1)]
        self._lane_works = [
            (
                np.empty(sl.stop - sl.start),
                np.empty((4, sl.stop - sl.start)),
                np.empty(7),
                np.empty(4),
                np.empty(STATE_SIZE),
            )
            for sl in self._slices
        ]
        # per thread, contiguous copies of its columns of the (k, N) arrays (the kernels run faster on them)
        self._columns = (
            [
                tuple(np.empty((k, sl.stop - sl.start)) for k in (STATE_SIZE, 4, STATE_SIZE, STATE_SIZE, n_terms, 4))
                for sl in self._slices
            ]
            if threads > 1
            else []
        )
        self._pool: ThreadPoolExecutor | None = None
        self._pool_pid = 0

    # --- public state ---------------------------------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """The N packed states (N, 11) float64 (a copy)."""
        return self._Ys.T.copy()

    @property
    def target_vectors(self) -> np.ndarray:
        """The N targets (λ*, μ*, ϱ*, s3*) (N, 4) (a copy)."""
        return self._T.copy()

    def _actions(self, actions) -> np.ndarray:
        """``actions`` as an (N, n) float64 array, or a ``ValueError`` naming ``actions`` (not numbers, wrong shape)."""
        shape = (self.num_envs,) + self.single_action_space.shape
        try:
            return np.asarray(actions, dtype=np.float64).reshape(shape)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"actions: must be {shape} finite numbers in [-1, 1], got {actions!r:.80}") from None

    def controls(self, actions) -> np.ndarray:
        """The controls u = (τ1, τ2, τ3, f_ϱ) (N, 4) that ``actions`` (N, n) apply (clipped and scaled)."""
        A = self._actions(actions)
        A_out, U = np.empty_like(A), np.empty((4, self.num_envs))
        if not self._kernels.controls_batch(A, self.single_env.mask.astype(np.uint8), self.limits, A_out, U):
            raise ValueError("actions: must be finite numbers in [-1, 1]")
        return U.T.copy()

    @property
    def episode_steps(self) -> np.ndarray:
        """Each body's steps into its current episode (N,) int64 (a copy); it truncates at ``max_episode_steps``."""
        return self._steps.copy()

    def set_episode_steps(self, steps) -> None:
        """Set each body's episode clock (N,) (integers in [0, ``max_episode_steps``)), e.g. to stagger the
        bodies' truncations (Isaac Lab's ``episode_length_buf``); ``reset(options={"stagger": True})`` draws them."""
        s = np.asarray(steps)
        if (
            s.shape != (self.num_envs,)
            or not np.issubdtype(s.dtype, np.integer)
            or (s < 0).any()
            or (s >= self.max_episode_steps).any()
        ):
            raise ValueError(f"steps: must be {self.num_envs} integers in [0, {self.max_episode_steps})")
        self._steps[:] = s

    # --- helpers -----------------------------------------------------------------------------------------
    @property
    def witnesses(self) -> list[np.ndarray | None]:
        """Each body's witness for the current episode (actions (steps, n) into the success ball at the last
        step; :class:`~flatbody_env.env.witness.ReachWithWitness`), None where the task has none."""
        return [None if w is None else w.copy() for w in self._witnesses]

    @property
    def bodies(self) -> list:
        """Each body's :class:`~flatbody_env.physics.body.Body` (the same one unless the task draws a body per episode)."""
        return list(self._bodies) if self._bodies is not None else [self.body] * self.num_envs

    def _start(self, i: int, ep: Episode, sc: np.ndarray) -> np.ndarray:
        """Start body i's drawn episode exactly as a single env would; its scalars go to ``sc[:, i]``; returns its observation."""
        p = self.single_env
        if self._bodies is not None:
            body = ep.body if ep.body is not None else p.body
            p.use_body(body)
            self._bodies[i] = body
            self._lane_steppers[i] = p.stepper
            self._lane_P[:, i] = p.kernel_params
        self._Ys[:, i] = ep.state
        self._T[i] = ep.target[:4]
        self._steps[i] = 0
        self._witnesses[i] = ep.witness
        obs, info = p.observe(ep.state, self._T[i])
        self._OBS_EXTRA[i] = obs[OBSERVATION_SIZE:]
        sc[0, i], sc[1, i], sc[2, i] = info["distance"], info["energy"], info["casimir"]
        return obs

    def _reset_many(self, idx: np.ndarray, options: dict[str, Any] | None, sc: np.ndarray, obs: np.ndarray) -> None:
        """Reset the bodies ``idx`` exactly as single envs would (their scalars into ``sc[:, idx]``, their
        observations into ``obs[idx]``): through the episode sampler's kernels for all of them at once
        where it applies (:class:`~flatbody_env.env.sampling.EpisodeSampler`), else by the task's draws
        (:meth:`~flatbody_env.env.env.FlatBodyEnv.draw_episodes`, all of them at once)."""
        if idx.size == 0:
            return
        if options or not (self.task.compiled_resets and self.single_env.sampler.applies):
            episodes = self.single_env.draw_episodes([self._rngs[i] for i in idx], options)
            for i, ep in zip(idx, episodes):
                obs[i] = self._start(int(i), ep, sc)
            return
        TG = self.single_env.sampler.sample([self._rngs[i] for i in idx], self._Ys, idx)
        self._T[idx] = TG[:, :4]
        self._steps[idx] = 0
        m = idx.size
        Y = np.ascontiguousarray(self._Ys[:, idx])
        p = self.single_env
        OBS, SC, TERMS = (
            np.empty((m, p.observation_size), dtype=np.float32),
            np.empty((4, m)),
            np.empty((len(self.reward_names), m)),
        )
        self._kernels.post_step_lanes(
            Y,
            Y,
            np.zeros(m, np.int64),
            np.zeros((m, 1)),
            0,
            np.ascontiguousarray(self._T[idx]),
            p.kernel_config,
            p.kernel_params,
            np.empty_like(Y),
            OBS,
            TERMS,
            SC,
            np.empty(m, np.int64),
            np.empty(m),
            np.empty((4, m)),
            np.empty(7),
            np.empty(4),
            np.empty(STATE_SIZE),
        )
        OBS[:, OBSERVATION_SIZE:] = self._OBS_EXTRA[idx]
        if np.any(SC[3] != 0):
            p.check_start(Y[:, int(np.flatnonzero(SC[3] != 0)[0])], "initial_noise")
        if p.custom_potential is not None:
            SC[1] += p.energy_left_out(Y)
        obs[idx] = OBS
        sc[:3, idx] = SC[:3]

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_pool"] = None  # threads are not pickled: started again on the first step
        return state

    def _advance_bodies(self) -> None:
        """Advance, check and score each body with its own body's stepper and kernel parameters (a task that
        draws a body per episode): the single env's step, body by body."""
        p = self.single_env
        k = self._kernels
        n_act = self._A.shape[1]
        y, u, ynew, yout = np.empty(STATE_SIZE), np.empty(4), np.empty(STATE_SIZE), np.empty(STATE_SIZE)
        counters, terms, sc = np.zeros(3, np.int64), np.empty(len(self.reward_names)), np.empty(4)
        vel, force = np.empty(7), np.empty(4)
        obs = np.empty(p.observation_size, dtype=np.float32)
        a = np.empty(n_act)
        for i in range(self.num_envs):
            y[:] = self._Ys[:, i]
            u[:] = self._U[:, i]
            a[:] = self._A[i]
            counters[:] = 0
            st = self._lane_steppers[i].advance(y, u, self.dt, ynew, counters)
            P = self._lane_P[:, i].copy()
            self._ENDED[i] = k.post_step(
                y, ynew, st, a, n_act, self._T[i].copy(), p.kernel_config, P, yout, obs, terms, sc, vel, force
            )
            self._STATUS[i] = st
            self._NFEV[i] = counters[0]
            self._OUT[:, i] = ynew
            self._Ynext[:, i] = yout
            self._OBS[i] = obs
            self._TERMS[:, i] = terms
            self._SC[:, i] = sc

    def _advance(self, c: int) -> None:
        """Advance, check and score the bodies of slice ``c`` (thread-safe: disjoint slices, own work arrays)."""
        sl = self._slices[c]
        p = self.single_env
        if self.num_threads == 1:
            Ys, U, OUT, STATUS, NFEV, A, T = self._Ys, self._U, self._OUT, self._STATUS, self._NFEV, self._A, self._T
            Ynext, OBS, TERMS, SC, ENDED = self._Ynext, self._OBS, self._TERMS, self._SC, self._ENDED
        else:  # this thread's columns, copied into contiguous arrays and back
            Ys, U, OUT, Ynext, TERMS, SC = self._columns[c]
            np.copyto(Ys, self._Ys[:, sl])
            np.copyto(U, self._U[:, sl])
            STATUS, NFEV, A, T, OBS, ENDED = (
                self._STATUS[sl],
                self._NFEV[sl],
                self._A[sl],
                self._T[sl],
                self._OBS[sl],
                self._ENDED[sl],
            )
        self._steppers[c].advance_batch(Ys, U, self.dt, OUT, STATUS, NFEV)
        self._kernels.post_step_lanes(
            Ys,
            OUT,
            STATUS,
            A,
            A.shape[1],
            T,
            p.kernel_config,
            p.kernel_params,
            Ynext,
            OBS,
            TERMS,
            SC,
            ENDED,
            *self._lane_works[c],
        )
        if p.custom_potential is not None:  # its part of H (the kernels know the built-in potentials only)
            SC[1] += p.energy_left_out(Ynext)
        if self.num_threads > 1:
            self._OUT[:, sl] = OUT
            self._Ynext[:, sl] = Ynext
            self._TERMS[:, sl] = TERMS
            self._SC[:, sl] = SC

    # --- VectorEnv API ------------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset every body, or those of ``options["reset_mask"]``; ``options["stagger"]``: start the reset bodies'
        clocks at random steps (module docstring). Other options are the single env's (``target``, ``state``)."""
        n = self.num_envs
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        stagger = bool(options.pop("stagger", False))
        options = options or None
        if mask is None:
            idx = np.arange(n)
        else:
            mask = np.asarray(mask)
            if mask.shape != (n,) or mask.dtype != np.bool_:
                raise ValueError(f"options.reset_mask: must be a bool array of shape ({n},)")
            idx = np.flatnonzero(mask)
        if seed is not None:
            seeds = list(seed) if isinstance(seed, (list, tuple)) else [seed + i for i in range(n)]
            if len(seeds) != n:
                raise ValueError(f"seed: expected {n} seeds, got {len(seeds)}")
            for i in idx.tolist():
                self._rngs[i] = seeding.np_random(seeds[i])[0]
        obs = self._cur_obs.copy()
        sc = self._cur_sc.copy()
        self._reset_many(idx, options, sc, obs)
        self._autoreset[idx] = False
        if stagger and idx.size:  # a generator of its own: the episode draws stay those of single envs
            rng = np.random.default_rng(None if seed is None or not isinstance(seed, int) else (seed, 0x57A6))
            self._steps[idx] = rng.integers(0, self.max_episode_steps, idx.size)
        self._cur_obs[:] = obs
        self._cur_sc[:] = sc
        blank = np.array([""] * n, dtype=object)
        info = build_info(
            t=self._steps * self.dt,
            scalars=sc,
            p_theta=self._Ys[3],
            ended=np.zeros(n, dtype=bool),
            failure=blank,
            left=blank.copy(),
            method=self.stepper.method,
            nfev=np.zeros(n, np.int64),
            terms=None,
            success_tolerance=self.task.success_tolerance,
        )
        return obs, info

    def step(self, actions):
        A = self._actions(actions)
        k = self._kernels
        p = self.single_env
        if not k.controls_batch(A, self._mask_u8, self.limits, self._A, self._U):
            raise ValueError("actions: must be finite numbers in [-1, 1]")
        resetting = self._autoreset.copy()
        if self._bodies is not None:
            self._advance_bodies()
        elif self.num_threads == 1:
            self._advance(0)
        else:
            if self._pool is None or self._pool_pid != os.getpid():  # (re)started lazily, also after a fork
                self._pool = ThreadPoolExecutor(max_workers=self.num_threads - 1, thread_name_prefix="flatbody-vector")
                self._pool_pid = os.getpid()
            futures = [self._pool.submit(self._advance, c) for c in range(1, self.num_threads)]
            self._advance(0)
            for f in futures:
                f.result()
        self._OBS[:, OBSERVATION_SIZE:] = self._OBS_EXTRA
        status = self._STATUS
        leaves = np.zeros(self.num_envs, dtype=bool)
        if self._own_terms:  # the task's own termination and terms (as the single env: FlatBodyEnv.step)
            leaves = self.task.leaves(self._SC[0], self._ENDED.astype(bool))
            self.task.extra_terms(self._ENDED.astype(bool) | leaves, leaves, self._TERMS)
        ended = (self._ENDED.astype(bool) | leaves) & ~resetting
        failures = self._blank.copy()
        lefts = self._blank.copy()
        for i in np.flatnonzero(ended):
            if leaves[i]:
                lefts[i] = p.describe_leaving(float(self._SC[0, i]))
            elif status[i] != 0:
                failures[i] = self.stepper.describe(int(status[i]), lane=int(i))
            else:
                lefts[i] = p.left_domain(self._OUT[:, i]) or ""
        keep = ~resetting
        if resetting.any():
            np.copyto(self._Ys, self._Ynext, where=keep)
        else:  # no body resets in this step (most steps): a plain copy
            np.copyto(self._Ys, self._Ynext)
        self._steps += keep
        terminated = ended
        truncated = (self._steps >= self.max_episode_steps) & ~terminated & keep
        obs = self._OBS.copy()
        rewards = self._TERMS.sum(axis=0)
        terms = dict(zip(self.reward_names, self._TERMS.copy()))
        sc = self._SC.copy()
        nfev = self._NFEV.copy()
        idx = np.flatnonzero(resetting)
        if idx.size:
            rewards[idx] = 0.0
            for v in terms.values():
                v[idx] = 0.0
            nfev[idx] = 0
            self._reset_many(idx, None, sc, obs)
        t = self._steps * self.dt
        done = terminated | truncated
        same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        if same_step:
            final_obs = obs.copy()
            sc_now = sc.copy()
            self._reset_many(np.flatnonzero(done), None, sc_now, obs)
            self._autoreset[:] = False
        else:
            sc_now = sc
            self._autoreset = done
        self._cur_obs[:] = obs
        self._cur_sc[:] = sc_now
        info = build_info(
            t=t,
            scalars=sc,
            p_theta=self._Ys[3],
            ended=ended,
            failure=failures,
            left=lefts,
            method=self.stepper.method,
            nfev=nfev,
            terms=terms,
            success_tolerance=self.task.success_tolerance,
        )
        if same_step:
            info["final_obs"] = final_obs
            info["_final_obs"] = done.copy()
        return obs, rewards, terminated, truncated, info

    def close_extras(self, **kwargs: Any) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        self.single_env.close()


__all__ = ["FlatBodyVectorEnv"]
