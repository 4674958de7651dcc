"""``FlatBodyVectorEnv``: N bodies of any task of docs/tasks.md, natively batched — Gymnasium's vector face of the
one transition (:mod:`flatbody_env.env.transition`, run by :class:`~flatbody_env.env.core.EnvCore`).

Sub-environment ``i`` reset with ``seed=s`` draws exactly what a single env reset with ``seed=s + i`` draws, so N
single environments and one vector environment produce the same rollouts step for step (tested, for every
registered id). It truncates by itself after ``max_episode_steps`` and autoresets in Gymnasium's default
NEXT_STEP mode (the step after a body's episode ended resets that body: its action is ignored, reward 0,
terminated = truncated = False), or in SAME_STEP mode (``autoreset_mode``): a body whose episode ends is reset
within the same step, its last observation in ``info["final_obs"]`` (rows flagged by ``info["_final_obs"]``).

Episode statistics, as Gymnasium's ``RecordEpisodeStatistics`` would add them (so do not wrap this env in it):
``info["episode"]`` = {``r``: return, ``l``: length in steps, ``is_success``, ``distance``: the final distance}
of the episodes that ended in this step, rows flagged by ``info["_episode"]``; and rsl_rl's ``extras["log"]`` as
``info["log"]`` (their means, where any ended).

Episode clocks and partial resets (Isaac Lab's episode-length randomisation): ``reset(options={"stagger": True})``
starts every reset body's clock at a uniform random step in [0, ``max_episode_steps``) (drawn from the body's own
counter-based stream: the episode draws are unchanged); :attr:`~FlatBodyVectorEnv.episode_steps` reads the clocks and
:meth:`~FlatBodyVectorEnv.set_episode_steps` sets them. ``reset(options={"reset_mask": m})`` (Gymnasium's convention)
resets only the bodies where the bool mask ``m`` (N,) is set (re-seeded with ``seed + i`` when ``seed`` is given); the
others keep their state, clock and observation.

Threads (``num_threads``; None: one per available core, at least :data:`LANES_PER_THREAD` bodies each; default 1):
the batch is split into contiguous blocks of bodies, each a core of its own stepped in its own thread (the compiled
loops release the GIL); the result does not depend on the split (each body's arithmetic is its own; tested).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from flatbody_env.env import transition as tr
from flatbody_env.env.core import EnvCore, configure, target_of
from flatbody_env.env.registration import MAX_EPISODE_STEPS
from flatbody_env.physics import validation

LANES_PER_THREAD = 256
"""Fewest bodies per thread of the automatic split (below that a thread costs more than it saves)."""
MAX_THREADS = 64
"""Largest ``num_threads`` accepted."""
INFO_ROWS = (slice(3, 4), slice(tr.R_REWARD, tr.S_ROWS))
"""The rows of ``S`` that :func:`episode_info` copies (and a step's returns read): p_θ, and the reward to the episode's
end figures."""


def available_cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def batch_arguments(
    num_envs, max_episode_steps, autoreset_mode, *, max_batch: int | None = None
) -> tuple[int, int, AutoresetMode]:
    """The batch's size, episode length and autoreset mode, checked before any allocation (shared by
    :class:`FlatBodyVectorEnv` and the torch vector env). ValueError naming the argument and its range."""
    num_envs = validation.count("num_envs", num_envs, high=max_batch or validation.MAX_BATCH)
    max_episode_steps = validation.count("max_episode_steps", max_episode_steps, high=validation.MAX_EPISODE_STEPS)
    try:
        mode = AutoresetMode(autoreset_mode)
    except ValueError:
        mode = None  # not a mode at all: refused below, without the enum's error as context
    validation.requirement(
        "autoreset_mode",
        autoreset_mode,
        mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP),
        "be NextStep or SameStep",
    )
    return num_envs, max_episode_steps, mode


def seed_list(seed, n: int) -> list[int] | None:
    """Per-body seeds of ``reset(seed=...)``: an int s gives s, s + 1, …; a list gives itself (length n); None keeps
    each body's stream. ValueError naming ``seed``."""
    if seed is None:
        return None
    if isinstance(seed, (list, tuple)):
        if len(seed) != n:
            raise ValueError(f"seed: expected {n} seeds, got {len(seed)}")
        return [validation.integer(f"seed[{i}]", s, low=0, high=validation.MAX_SEED) for i, s in enumerate(seed)]
    s = validation.integer("seed", seed, low=0, high=validation.MAX_SEED)
    return [s + i for i in range(n)]


LOG_MEANS = ("episode_return", "episode_length", "success_rate", "final_distance")
"""The means of ``info["log"]`` (rsl_rl's ``extras["log"]``) over the episodes that ended in a step."""


def episode_info(
    S: np.ndarray, K: np.ndarray, *, dt: float, tol: float, method: str, names, step: bool, xp=np
) -> dict[str, Any]:
    """The ``info`` of a step (or, ``step=False``, of a reset) of a batch from its arrays ``S``, ``K``
    (:mod:`flatbody_env.env.transition`; numpy arrays, or torch tensors with ``xp`` = torch): the one schema of every
    face (:class:`~flatbody_env.env.env.FlatBodyEnv`, "Info"). The rows it hands out are views of copies made here
    (:data:`INFO_ROWS` of ``S``, and ``K``), never of the env's own arrays."""
    copy = (lambda a: a.copy()) if xp is np else (lambda a: a.clone())
    (p_theta, rows), ints = (copy(S[r]) for r in INFO_ROWS), copy(K)

    def row(r):
        return rows[r - INFO_ROWS[1].start]

    done = ints[tr.K_EP_DONE] != 0
    clock = xp.where(done, ints[tr.K_EP_LENGTH], ints[tr.K_CLOCK]) if step else ints[tr.K_CLOCK]
    clock = clock.astype(np.float64) if xp is np else clock.double()
    d = row(tr.R_DISTANCE)
    info: dict[str, Any] = {
        "t": clock * dt,
        "distance": d,
        "is_success": (d <= tol) & (ints[tr.K_TERMINATED] == 0),
        "energy": row(tr.R_ENERGY),
        "casimir": row(tr.R_CASIMIR),
        "p_theta": p_theta[0],
        "integrator": {"method": method, "nfev": ints[tr.K_NFEV]},
        "status": ints[tr.K_STATUS],
        "domain_code": ints[tr.K_CODE],
    }
    if not step:
        return info
    info["reward_terms"] = {name: row(tr.R_TERMS + i) for i, name in enumerate(names)}
    ret, length, ok, dist = row(tr.R_EP_RETURN), ints[tr.K_EP_LENGTH], ints[tr.K_EP_SUCCESS] != 0, row(tr.R_EP_DISTANCE)
    info["episode"] = {"r": ret, "l": length, "is_success": ok, "distance": dist}
    info["_episode"] = done
    if xp is np:
        count = int(np.count_nonzero(done))
        if count == 0:  # no episode ended: the log's means are 0 (read nothing)
            info["log"] = {"episodes": np.asarray(0), **{key: np.asarray(0.0) for key in LOG_MEANS}}
            return info
        w = done / count
    else:
        count = done.sum()
        w = done.double() / count.clamp(min=1)
    means = {key: xp.asarray((v * w).sum()) for key, v in zip(LOG_MEANS, (ret, length, ok, dist), strict=True)}
    info["log"] = {"episodes": xp.asarray(count), **means}  # 0-d arrays (tensors on the torch face): no sync to read
    return info


class FlatBodyVectorEnv(VectorEnv):
    """N bodies of one configuration (the keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv`) in one
    batched simulation (module docstring).

    Parameters
    ----------
    num_envs : int
        Number of bodies N.
    max_episode_steps : int
        Truncation horizon (400 = t 20 at dt 0.05, as registered).
    autoreset_mode : AutoresetMode
        ``NEXT_STEP`` (default, Gymnasium's default) or ``SAME_STEP`` (module docstring).
    num_threads : int or None
        Threads that step the bodies (1 ... :data:`MAX_THREADS`; default 1); None: one per available core, at most
        one per :data:`LANES_PER_THREAD` bodies. Always 1 when the integrator does not run compiled.
    **kwargs
        The keyword arguments of :class:`~flatbody_env.env.env.FlatBodyEnv` (``render_mode`` and ``track_rotation``
        are not supported here).
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
        if num_threads is not None:
            num_threads = validation.integer("num_threads", num_threads, low=1, high=MAX_THREADS)
        if kwargs.get("render_mode") is not None or kwargs.get("track_rotation"):
            raise ValueError("render_mode: FlatBodyVectorEnv does not render; use FlatBody-v1 for frames")
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self.config = c = configure(**kwargs)
        """The configuration all N bodies share (:class:`~flatbody_env.env.core.EnvConfig`)."""
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        if not getattr(c.stepper, "compiled", False):
            threads = 1  # a generic (Python) stepper holds the GIL: threads would only add their cost
        elif num_threads is None:
            threads = max(1, min(available_cores(), num_envs // LANES_PER_THREAD))
        else:
            threads = min(num_threads, num_envs)
        self.num_threads = threads
        """Threads that step the bodies (1: the calling thread alone)."""
        edges = np.linspace(0, num_envs, threads + 1).round().astype(int)
        self._slices = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
        reset = "same" if mode == AutoresetMode.SAME_STEP else "next"
        self.cores = [
            EnvCore(c, sl.stop - sl.start, max_episode_steps=max_episode_steps, autoreset=reset) for sl in self._slices
        ]
        """The cores that step the bodies, one per thread (:class:`~flatbody_env.env.core.EnvCore`)."""
        self.single_observation_space = c.observation_space
        self.single_action_space = c.action_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.reward_names = c.reward_names
        """The names of ``info["reward_terms"]`` (the task's)."""
        self._method = c.stepper.method
        self._pool: ThreadPoolExecutor | None = None
        self._info_buffers: tuple[np.ndarray, np.ndarray] | None = None
        self._pool_pid = 0

    # --- composition (read only) ---------------------------------------------------------------------
    body = property(lambda self: self.config.body, doc="The configuration's body (:attr:`bodies`: each body's).")
    task = property(lambda self: self.config.task)
    control = property(lambda self: self.config.control)
    limits = property(lambda self: self.config.limits)
    dt = property(lambda self: self.config.dt)
    stepper = property(lambda self: self.config.stepper)

    def _gather(self, name: str, rows=None) -> np.ndarray:
        """Array ``name`` of every core, bodies in order (columns of ``S``/``K``, rows of ``OBS``/``FINAL``)."""
        parts = [getattr(core, name) for core in self.cores]
        if name in ("S", "K"):
            parts = [p if rows is None else p[rows] for p in parts]
            return parts[0].copy() if len(parts) == 1 else np.concatenate(parts, axis=-1)
        return parts[0].copy() if len(parts) == 1 else np.concatenate(parts, axis=0)

    # --- public state ---------------------------------------------------------------------------------
    @property
    def observations(self) -> np.ndarray:
        """The N current observations (N, d) (a copy), as the last reset or step returned them, the observed time
        (``observe_time``) updated by :meth:`set_episode_steps` since."""
        return self._gather("OBS")

    @property
    def states(self) -> np.ndarray:
        """The N packed states (N, 11) float64 (a copy)."""
        return self._gather("S", slice(tr.Y0, tr.Y0 + 11)).T.copy()

    @property
    def target_vectors(self) -> np.ndarray:
        """The N targets (λ*, μ*, ϱ*, s3*) (N, 4) (a copy)."""
        return self._gather("S", slice(tr.TG0, tr.TG0 + 4)).T.copy()

    def targets(self) -> list:
        """Each body's target stationary ellipse (full records,
        :class:`~flatbody_env.physics.equilibria.StationaryEllipse`)."""
        return [target_of(core, i) for core in self.cores for i in range(core.num_envs)]

    @property
    def witnesses(self) -> list[np.ndarray | None]:
        """Each body's witness for the current episode (actions (steps, n) into the success ball at the last step;
        :class:`~flatbody_env.env.witness.ReachWithWitness`), None where the task has none."""
        if self.config.task.kind != tr.TASK_WITNESS:
            return [None] * self.num_envs
        from flatbody_env.env.witness import witness_actions

        W = self._gather("S", slice(tr.W0, tr.W0 + 9))
        return [
            witness_actions(W[:, i], self.config.task.witness_steps, self.config.n_act) for i in range(self.num_envs)
        ]

    @property
    def bodies(self) -> list:
        """Each body's :class:`~flatbody_env.physics.body.Body` (the same one unless the task draws a body per
        episode)."""
        return [core.body_of(i) for core in self.cores for i in range(core.num_envs)]

    @property
    def body_params(self) -> np.ndarray:
        """Each body's kernel parameters (9, N) (:meth:`flatbody_env.physics.body.Body.kernel_params`; a copy): the
        model of the episode's body, also where the observation hides it (``FlatBodyAnyBody-v1``)."""
        return self._gather("S", slice(tr.P0, tr.P0 + 9))

    @property
    def episode_steps(self) -> np.ndarray:
        """Each body's steps into its current episode (N,) int64 (a copy); it truncates at ``max_episode_steps``."""
        return self._gather("K", tr.K_CLOCK)

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
            raise validation.refusal("steps", f"be {self.num_envs} integers in [0, {self.max_episode_steps})", steps)
        for core, sl in zip(self.cores, self._slices, strict=True):
            core.set_clocks(s[sl])

    def _actions(self, actions) -> np.ndarray:
        """``actions`` as an (N, n) float64 array of finite numbers, or a ``ValueError`` naming ``actions``."""
        shape = (self.num_envs, *self.single_action_space.shape)
        try:
            a = np.asarray(actions)
            ok = a.shape == shape and a.dtype.kind in "fiu" and a.dtype != np.bool_
            a = np.asarray(a, dtype=np.float64) if ok else None
        except (TypeError, ValueError, OverflowError):
            a = None
        if a is None or not np.isfinite(a).all():
            raise validation.refusal("actions", f"be {shape} finite real numbers in [-1, 1]", actions)
        return a

    def controls(self, actions) -> np.ndarray:
        """The controls u = (τ1, τ2, τ3, f_ϱ) (N, 4) that ``actions`` (N, n) apply (clipped and scaled)."""
        return self.config.controls(self._actions(actions))[1]

    # --- VectorEnv API ------------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset every body, or those of ``options["reset_mask"]``; ``options["stagger"]``: start the reset bodies'
        clocks at random steps (module docstring). Other options are the single env's (``target``, ``state``)."""
        n = self.num_envs
        options = {} if options is None else dict(validation.mapping("options", options))
        mask = options.pop("reset_mask", None)
        stagger = options.pop("stagger", False)
        validation.boolean("options.stagger", stagger)
        if mask is None:
            mask = np.ones(n, dtype=bool)
        else:
            mask = np.asarray(mask)
            validation.requirement(
                "options.reset_mask",
                mask,
                mask.shape == (n,) and mask.dtype == np.bool_,
                f"be a bool array of shape ({n},)",
            )
        seeds = seed_list(seed, n)
        for core, sl in zip(self.cores, self._slices, strict=True):
            core.reset(
                seeds=None if seeds is None else seeds[sl],
                mask=mask[sl],
                options=options or None,
                stagger=bool(stagger),
            )
        return self._gather("OBS"), self._info(step=False)

    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``S`` and ``K`` of all bodies for :func:`episode_info` and the step's returns, read only: one core's own
        arrays (no copy: :func:`episode_info` copies every row it hands out), else the rows they read (:data:`INFO_ROWS`
        of ``S``, all of ``K``) of every core gathered into buffers this env keeps (the other rows of ``S`` are not
        filled)."""
        if len(self.cores) == 1:
            return self.cores[0].S, self.cores[0].K
        if self._info_buffers is None:
            self._info_buffers = (np.zeros((tr.S_ROWS, self.num_envs)), np.zeros((tr.K_ROWS, self.num_envs), np.int64))
        S, K = self._info_buffers
        for core, sl in zip(self.cores, self._slices, strict=True):
            for rows in INFO_ROWS:
                S[rows, sl] = core.S[rows]
            K[:, sl] = core.K
        return S, K

    def _info(self, *, step: bool, arrays=None) -> dict[str, Any]:
        S, K = arrays if arrays is not None else self._arrays()
        return episode_info(
            S,
            K,
            dt=self.config.dt,
            tol=self.config.task.success_tolerance,
            method=self._method,
            names=self.reward_names,
            step=step,
        )

    def step(self, actions):
        A = self._actions(actions)
        if self.num_threads == 1:
            self.cores[0].step(A)
        else:
            if self._pool is None or self._pool_pid != os.getpid():  # (re)started lazily, also after a fork
                self._pool = ThreadPoolExecutor(max_workers=self.num_threads - 1, thread_name_prefix="flatbody-vector")
                self._pool_pid = os.getpid()
            parts = [np.ascontiguousarray(A[sl]) for sl in self._slices]
            futures = [self._pool.submit(core.step, a) for core, a in zip(self.cores[1:], parts[1:], strict=True)]
            self.cores[0].step(parts[0])
            for f in futures:
                f.result()
        S, K = self._arrays()
        info = self._info(step=True, arrays=(S, K))
        terminated = K[tr.K_TERMINATED] != 0
        truncated = K[tr.K_TRUNCATED] != 0
        if self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP:
            info["final_obs"] = self._gather("FINAL")
            info["_final_obs"] = terminated | truncated
        return self._gather("OBS"), S[tr.R_REWARD].copy(), terminated, truncated, info

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_pool"] = None  # threads are not pickled: started again on the first step
        return state

    def close_extras(self, **kwargs: Any) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


__all__ = ["FlatBodyVectorEnv", "batch_arguments", "episode_info", "seed_list"]
