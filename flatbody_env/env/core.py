"""The environment's configuration and the batch that every face steps: :class:`EnvConfig` and :class:`EnvCore`.

:func:`configure` turns the keyword arguments of ``gym.make(ID, ...)`` into an :class:`EnvConfig` — the body,
the integrator (chosen by name through :func:`flatbody_env.integrators.steppers.make_env_step`) and the task
(dm_control's split), the control limits, the domain, the kernels' configuration vectors and the spaces.
:class:`EnvCore` holds N bodies of one configuration in the arrays of :mod:`flatbody_env.env.transition` and
runs that module's per-body transition on them — on the CPU (the compiled loops) or on CUDA (one launch per
step). It is the only place a step happens:

* :class:`~flatbody_env.env.env.FlatBodyEnv` is a core of one body (no truncation, no autoreset: Gymnasium's
  ``TimeLimit`` truncates);
* :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv` a core of N bodies with its episode length and
  autoreset mode;
* :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv` the vector env's arrays as tensors
  (CPU), or a core on CUDA whose arrays are torch tensors.

On the CPU a step is one compiled call per batch (:func:`~flatbody_env.env.transition.step_lanes`), or, where
a batched integrator computes the same numbers faster (the fused structure-of-arrays DOP853 of
:mod:`flatbody_env.integrators.batch_kernels`, for one body or, where the task draws a body per episode, with each
body's own parameters) or the method has no per-body kernel (scipy's methods, a custom
potential, R carried for rendering), three: :func:`~flatbody_env.env.transition.controls_lanes`, the seam's
stepper, :func:`~flatbody_env.env.transition.finish_lanes` — the same per-body functions, bit for bit.

Draws: the v1 ids draw in the transition (counter-based, the same on every face and device); the v0 ids keep
their own draws, on the host, from each body's numpy generator (:meth:`EnvCore.host_draw`), exactly as
before, so their saved reports reproduce.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from gymnasium import spaces

from flatbody_env.env import transition as tr
from flatbody_env.env.registration import MAX_EPISODE_STEPS, TASK_CLASSES
from flatbody_env.env.sampling import draw_config
from flatbody_env.env.task import (
    CONTROLS,
    TASK_WITNESS,
    Episode,
    ReachStationaryEllipse,
    control_mask,
    domain_code,
    target_row,
)
from flatbody_env.integrators import Tolerances, get_method
from flatbody_env.integrators.steppers import make_env_step
from flatbody_env.physics import validation
from flatbody_env.physics.body import Body, default_body
from flatbody_env.physics.equilibria import StationaryEllipse, stationary_from_shape
from flatbody_env.physics.potentials import KIND_CUSTOM
from flatbody_env.physics.state import STATE_NAMES, pack, validate_state

DEFAULT_INTEGRATOR = "DOP853-numba"
"""Default integrator: compiled DOP853 at rtol = atol = :data:`DEFAULT_TOLERANCE`, first step guessed
as one env step — the fastest method measured to keep the episode state error ≤ 1e-8 and to survive
close approaches to λ = μ (docs/env.md, "The default integrator and its measured error"; ``flatbody bench env``
re-measures the episode error)."""
DEFAULT_TOLERANCE = 1e-11
"""rtol = atol of the default integrator (see :data:`DEFAULT_INTEGRATOR`)."""
ROTATION_INTEGRATOR = "DOP853"
"""Integrator used when R must be carried (rendering, recording) and the chosen method refuses to
step this body at all (e.g. a compiled method with a custom potential); ``info["integrator"]["method"]``
then names it."""
HOST_DRAW_CHUNK = 1024
"""Bodies whose v0 draws run together (the witnessed starts' reversed runs hold witness_steps × chunk × n actions)."""
FUSED_MIN_BODIES = 32
"""Batches of at least this many bodies step through the fused structure-of-arrays DOP853 where it applies
(below, the per-body loop is as fast)."""
END_REASONS = {
    0: "",
    1: "non-finite state",
    2: "lambda left the domain",
    3: "mu left the domain",
    4: "rho left the domain",
    5: "a momentum beyond its bound",
    6: "lambda = mu (the two-polar chart's gap)",
    tr.CODE_LEFT_TOLERANCE: "left the target's tolerance",
}
"""``info["domain_code"]`` → what ended the episode (:func:`end_reason`)."""


@dataclass(frozen=True, kw_only=True)
class EnvConfig:
    """One environment's composition: body + integrator + task, and what follows from them (:func:`configure`)."""

    body: Body
    task: ReachStationaryEllipse
    control: str
    mask: np.ndarray
    limits: np.ndarray
    dt: float
    integrator: str
    tolerances: Tolerances
    stepper: Any
    stretch_bounds: tuple[float, float]
    rho_bounds: tuple[float, float]
    momentum_bound: float
    gap_min: float
    track_rotation: bool
    render_mode: str | None
    custom_potential: Any
    kcfg: np.ndarray
    action_space: spaces.Box
    observation_space: spaces.Box

    @property
    def observation_size(self) -> int:
        return int(self.observation_space.shape[0])

    @property
    def n_act(self) -> int:
        return int(self.action_space.shape[0])

    @property
    def reward_names(self) -> tuple[str, ...]:
        return self.task.reward_names

    @property
    def kernel_draws(self) -> bool:
        """Whether the transition draws the episodes (the v1 ids) rather than the host (the v0 ids)."""
        return self.task.draws == "philox"

    def controls(self, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The clipped actions (N, n) and the controls u = (τ1, τ2, τ3, f_ϱ) (N, 4) that the finite actions ``A``
        (N, n) apply: the transition's arithmetic (:func:`~flatbody_env.env.transition.controls_body`)."""
        m = self.mask
        clipped = np.clip(A, -1.0, 1.0) if m.any() else np.zeros_like(A)
        U = np.zeros((A.shape[0], 4))
        U[:, m] = clipped[:, : int(m.sum())] * self.limits[m]
        return clipped, U

    def left_domain(self, y: np.ndarray) -> str | None:
        """None inside the documented domain, else what left it (:func:`~flatbody_env.env.task.domain_code`)."""
        code = domain_code(y, self.kcfg)
        if code == 0:
            return None
        if code == 1:
            return "non-finite state"
        lo, hi = self.stretch_bounds
        if code in (2, 3):
            name, k = ("lambda", 7) if code == 2 else ("mu", 8)
            return f"{name} = {y[k]:.4g} outside [{lo:g}, {hi:g}]"
        if code == 4:
            return f"rho = {y[9]:.4g} outside [{self.rho_bounds[0]:g}, {self.rho_bounds[1]:g}]"
        if code == 5:
            k = int(np.argmax(np.abs(y[:7]) > self.momentum_bound))
            return f"{STATE_NAMES[k]} = {y[k]:.4g} beyond the momentum bound {self.momentum_bound:g}"
        return f"|lambda - mu|/(lambda + mu) < gap_min = {self.gap_min:g} (two-polar chart singular at lambda = mu)"

    def check_start(self, y: np.ndarray, field: str) -> None:
        """ValueError naming ``field`` when the initial state ``y`` lies outside the domain."""
        left = self.left_domain(y)
        if left:
            raise ValueError(f"{field}: the initial state starts outside the domain ({left})")


def configure(
    control: str = "torque+dilatation",
    task: str | ReachStationaryEllipse = "reach",
    body: Body | Mapping[str, Any] | None = None,
    dt: float = 0.05,
    integrator: str = DEFAULT_INTEGRATOR,
    rtol: float = DEFAULT_TOLERANCE,
    atol: float = DEFAULT_TOLERANCE,
    step: float | None = None,
    torque_limit: float = 0.5,
    force_limit: float = 1.0,
    render_mode: str | None = None,
    track_rotation: bool = False,
    stretch_bounds: tuple[float, float] = (0.2, 4.0),
    rho_bounds: tuple[float, float] = (0.1, 4.0),
    momentum_bound: float = 50.0,
    gap_min: float = 1e-3,
    **task_kwargs: Any,
) -> EnvConfig:
    """The :class:`EnvConfig` of ``gym.make``'s keyword arguments (documented on
    :class:`~flatbody_env.env.env.FlatBodyEnv`);
    ValueError naming the keyword and its range for anything outside the documented ranges."""
    validation.string("control", control, choices=CONTROLS)
    mask = control_mask(control)
    task = _as_task(task, task_kwargs)
    if task.varies_body and body is not None:
        raise ValueError("body: this task draws its own body at every reset (leave body unset)")
    body = _as_body(body)
    custom = body.potential if getattr(body.potential, "kind", None) == KIND_CUSTOM else None
    if not body.inertia.is_isotropic:
        raise ValueError("body: the task's stationary ellipses need J1 = J2 (isotropic in the plane)")
    for name, value in (
        ("torque_limit", torque_limit),
        ("force_limit", force_limit),
        ("momentum_bound", momentum_bound),
    ):
        validation.number(name, value, low=validation.PARAM_RANGE[0], high=validation.MOMENTUM_MAX)
    for name, pair in (("stretch_bounds", stretch_bounds), ("rho_bounds", rho_bounds)):
        validation.interval(name, pair, low=validation.STRETCH_RANGE[0], high=validation.STRETCH_RANGE[1])
    validation.number("gap_min", gap_min, low=0.0, high=0.5)
    if render_mode is not None:
        validation.string("render_mode", render_mode, choices=("rgb_array",))
    validation.boolean("track_rotation", track_rotation)
    dt = validation.number("dt", dt, low=validation.ENV_DT_RANGE[0], high=validation.ENV_DT_RANGE[1])
    validation.string("integrator", integrator)
    method = get_method(integrator, where="integrator")  # the one look-up: the seam gets the method itself
    info = method.info
    track = bool(track_rotation or render_mode is not None)
    if not info.adaptive and step is None:
        step = dt  # one fixed step per env step unless step= asks for sub-steps
    if step is not None:  # bounded work: a floor (never replaced) and at most ENV_MAX_SUBSTEPS sub-steps per env step
        step = validation.fixed_step("step", step, high=dt)
        if math.ceil(dt / step) > validation.ENV_MAX_SUBSTEPS:
            raise ValueError(
                f"step: at most {validation.ENV_MAX_SUBSTEPS} sub-steps per env step (step >= dt / "
                f"{validation.ENV_MAX_SUBSTEPS} = {dt / validation.ENV_MAX_SUBSTEPS:g}), got step = {step!r}"
            )
    tolerances = Tolerances(
        rtol=rtol,
        atol=atol,
        step=step,
        max_nfev=validation.ENV_STEP_MAX_NFEV,
        max_wall_time=validation.ENV_STEP_MAX_SECONDS,
    )
    first_step = dt if info.adaptive else 0.0  # adaptive methods: the first step guessed as one whole env step
    try:
        stepper = make_env_step(method, body, tolerances, with_rotation=track, first_step=first_step)
    except ValueError:
        if not track:
            raise
        # methods that do not carry R: drawing/recording integrates with the reference (info names it)
        stepper = make_env_step(ROTATION_INTEGRATOR, body, replace(tolerances, step=None), with_rotation=True)
    limits = np.array([torque_limit, torque_limit, torque_limit, force_limit], dtype=np.float64)
    sb = (float(stretch_bounds[0]), float(stretch_bounds[1]))
    rb = (float(rho_bounds[0]), float(rho_bounds[1]))
    kcfg = task.kernel_config(
        stretch_bounds=sb,
        rho_bounds=rb,
        momentum_bound=float(momentum_bound),
        gap_min=float(gap_min),
        check_gap=info.chart == "two-polar",
    )
    n_act = int(mask.sum()) or 1
    m = float(momentum_bound)
    xlo, xhi = task.observation_extra_bounds()
    low = np.array([-m] * 7 + [sb[0], sb[0], rb[0], -1.0, -1.0, sb[0], sb[0], rb[0], -m, *xlo], dtype=np.float32)
    high = np.array([m] * 7 + [sb[1], sb[1], rb[1], 1.0, 1.0, sb[1], sb[1], rb[1], m, *xhi], dtype=np.float32)
    config = EnvConfig(
        body=body,
        task=task,
        control=control,
        mask=mask,
        limits=limits,
        dt=dt,
        integrator=integrator,
        tolerances=tolerances,
        stepper=stepper,
        stretch_bounds=sb,
        rho_bounds=rb,
        momentum_bound=m,
        gap_min=float(gap_min),
        track_rotation=track,
        render_mode=render_mode,
        custom_potential=custom,
        kcfg=kcfg,
        action_space=spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32),
        observation_space=spaces.Box(low, high, dtype=np.float32),
    )
    if config.kernel_draws:  # the v1 ids draw in the transition: a built-in potential, reachability by the table or off
        if custom is not None:
            raise ValueError("body: a custom potential cannot be drawn by the v1 resets (use a built-in potential)")
        if task.compiled_targets and draw_config(task, body, limits, control) is None:
            raise _outside_the_table(config)
    return config


def end_reason(status: int, domain_code: int, method: str = "") -> str:
    """What ended an episode, from ``info["status"]`` (the integrator's, :data:`flatbody_env.integrators.failure.KINDS`)
    and ``info["domain_code"]``: "" when nothing did."""
    from flatbody_env.integrators.failure import KINDS, failure_reason

    if status:
        kind = KINDS[status] if 0 <= status < len(KINDS) else "failure"
        return f"integrator failure ({kind}: {failure_reason(status)})" + (f" in {method}" if method else "")
    return END_REASONS.get(int(domain_code), f"code {domain_code}") if domain_code else ""


class EnvCore:
    """N bodies of one :class:`EnvConfig`, reset and stepped by :mod:`flatbody_env.env.transition` (module docstring).

    Parameters
    ----------
    config : EnvConfig
    num_envs : int
    max_episode_steps : int or None
        Truncation horizon; None: never truncates (the single env: Gymnasium's ``TimeLimit`` does).
    autoreset : str
        ``"next"`` (NEXT_STEP), ``"same"`` (SAME_STEP) or ``"none"`` (the single env).
    backend : str
        ``"cpu"`` or ``"cuda"``.
    alloc : callable, optional
        ``alloc(shape, dtype)`` makes the arrays (default: numpy zeros, ``S`` and ``K`` in the lanes' layout of
        :func:`~flatbody_env.env.transition.lanes`; numba device arrays on CUDA; the torch face passes views of torch
        tensors).
    """

    def __init__(
        self, config: EnvConfig, num_envs: int = 1, *, max_episode_steps: int | None = None, autoreset: str = "none",
        backend: str = "cpu", alloc=None, threads_per_block: int | None = None,
    ) -> None:  # fmt: skip
        self.config = c = config
        self.num_envs = n = int(num_envs)
        self.backend = backend
        self.action_field = "actions"
        """The name a non-finite action is refused under (the single env's: ``action``)."""
        self.max_episode_steps = max_episode_steps
        self.autoreset = autoreset
        task, st = c.task, c.stepper
        validation.requirement("device", backend, backend in ("cpu", "cuda"), "be 'cpu' or 'cuda'")
        if task.varies_body and not _kernel_stepper(st) and n > 1:
            raise ValueError(
                f"integrator: {st.method!r} cannot step a body drawn per episode "
                f"(use one of {', '.join(_batch_kinds())})"
            )
        if backend == "cuda":
            why = self.device_unsupported()
            if why:
                raise ValueError(why)
        scfg = draw_config(c.task, c.body, c.limits, c.control)
        self.scfg = np.ascontiguousarray(scfg if scfg is not None else np.zeros(16), dtype=np.float64)
        kind, coeffs = _batch_kinds().get(st.method, (0, np.zeros(1)))
        self.coeffs = np.ascontiguousarray(coeffs, dtype=np.float64)
        self.xcfg = self._xcfg(kind)
        self._fused = None
        lanes_layout = backend == "cpu" and alloc is None  # S and K as transition.lanes lays them out
        if backend == "cpu":
            self._put = np.ascontiguousarray
            alloc = alloc or (lambda shape, dtype: np.zeros(shape, dtype))
        else:
            from flatbody_env.integrators import cuda as _cuda

            self._cuda = _cuda
            dev = _cuda.require()
            self._put = dev.to_device
            if alloc is None:

                def alloc(shape, dtype):
                    return dev.to_device(np.zeros(shape, dtype))

            self.threads_per_block = threads_per_block or _cuda.THREADS_PER_BLOCK
        if lanes_layout:
            self.S, self.K = tr.lanes(tr.S_ROWS, n), tr.lanes(tr.K_ROWS, n, np.int64)
        else:
            self.S = alloc((tr.S_ROWS, n), np.float64)
            self.K = alloc((tr.K_ROWS, n), np.int64)
        self.OBS = alloc((n, c.observation_size), np.float32)
        self.FINAL = alloc((n, c.observation_size), np.float32)
        self.FLAGS = alloc((2,), np.int64)
        self._write_rows(tr.P0, np.tile(np.asarray(c.body.kernel_params(), dtype=np.float64)[:, None], (1, n)))
        if backend == "cpu":
            self.CFG = tr.pack_config(self.xcfg, c.kcfg, self.scfg, self.coeffs)
            self._work = (np.zeros(tr.WF_SIZE), np.zeros(tr.WI_SIZE, np.int64))
            self._dev = (self.CFG, *self._work)
        else:
            self._dev = tuple(self._put(a) for a in (self.coeffs, c.kcfg, self.scfg, self.xcfg, *tr.TABLE))
        self.rngs: list[np.random.Generator | None] = [None] * n
        """Each body's numpy generator (the v0 ids' host draws)."""
        self.seeded = np.zeros(n, dtype=bool)
        self.R: np.ndarray | None = np.eye(3) if (c.track_rotation and n == 1) else None
        """R(t) (3×3) of a single body when carried (rendering, recording)."""
        self.targets: list[StationaryEllipse | None] = [None] * n
        """Each body's target as a full record where a draw built it (the v0 ids and ``options``)."""
        self._mode = self._step_mode()
        self._seam = None
        self._fast = None
        if self._mode == "lanes" and c.kernel_draws and c.custom_potential is None:
            self._fast = (tr.cpu("step_lanes"), (self.S, self.K, self.OBS, self.FINAL, self.FLAGS, *self._dev))
        self._stepper = c.stepper.own()
        """This core's stepper: the configuration's with work arrays of its own (the cores of a vector env step in
        threads at once, and the fused batch step writes its work arrays in place)."""
        if self._mode != "lanes" and backend == "cpu":
            self._AC = np.zeros((n, c.n_act))
            self._U = tr.lanes(4, n)
            self._OUT = tr.lanes(11, n)
            self._STATUS = np.zeros(n, np.int64)
            self._NFEV = np.zeros(n, np.int64)
            self._lanes = tr.lane_work(n)

    # --- configuration ---------------------------------------------------------------------------
    def _xcfg(self, kind: int) -> np.ndarray:
        c, task, st = self.config, self.config.task, self.config.stepper
        x = np.zeros(tr.X_SIZE)
        x[tr.X_DT] = c.dt
        x[tr.X_MAX_NFEV] = validation.ENV_STEP_MAX_NFEV
        x[tr.X_H] = float(getattr(st, "h", 0.0))
        x[tr.X_RTOL] = float(getattr(st, "rtol", c.tolerances.rtol))
        x[tr.X_ATOL] = float(getattr(st, "atol", c.tolerances.atol))
        x[tr.X_ETOL] = float(getattr(st, "energy_tol", math.inf))
        x[tr.X_KIND] = kind
        x[tr.X_LIMITS : tr.X_LIMITS + 4] = c.limits
        x[tr.X_MASK : tr.X_MASK + 4] = c.mask.astype(float)
        x[tr.X_NACT] = c.n_act
        x[tr.X_MAX_STEPS] = float(self.max_episode_steps) if self.max_episode_steps is not None else 2.0**62
        x[tr.X_SAME_STEP] = {"next": 0.0, "same": 1.0, "none": 2.0}[self.autoreset]
        x[tr.X_DRAWS] = tr.DRAWS_KERNEL if c.kernel_draws else tr.DRAWS_HOST
        x[tr.X_TASK] = task.kind
        x[tr.X_REWARD] = tr.REWARD_TOLERANCE if task.reward == "tolerance" else tr.REWARD_TERMS
        x[tr.X_NTERMS] = len(task.reward_names)
        x[tr.X_W_ALIVE] = float(getattr(task, "w_alive", 0.0))
        x[tr.X_BETA] = task.w_proximity
        x[tr.X_MARGIN] = task.proximity_margin
        x[tr.X_VARY_BODY] = 1.0 if task.varies_body else 0.0
        x[tr.X_OBS_BODY] = 1.0 if task.body_observation_names else 0.0
        if task.observe_time:
            x[tr.X_OBS_TIME] = c.observation_size - 1
            x[tr.X_TIME_UNIT] = MAX_EPISODE_STEPS
        if task.varies_body:
            x[tr.X_RANGES : tr.X_RANGES + 10] = task.ranges().ravel()
        if task.kind == TASK_WITNESS:
            x[tr.X_WIT : tr.X_WIT + 11] = (
                task.witness_steps, task.max_witness_attempts, *task.witness_radius, *task.witness_amplitude,
                *task.witness_half_period, *task.start_distance, task.min_uncontrolled_offset,
            )  # fmt: skip
        return x

    def _step_mode(self) -> str:
        """How a CPU step runs: ``"lanes"`` (one compiled call), ``"fused"`` (controls, the fused structure-of-arrays
        DOP853, finish) or ``"seam"`` (controls, the seam's stepper, finish: any method, R, a custom potential)."""
        c = self.config
        st = c.stepper
        if self.backend == "cuda":
            return "cuda"
        if c.custom_potential is not None or self.R is not None or not _kernel_stepper(st):
            return "seam"
        if self.num_envs >= FUSED_MIN_BODIES and getattr(st, "steps_bodies", False):
            return "fused"  # a task that draws a body per episode too: each lane's parameters go with it
        return "lanes"

    def device_unsupported(self) -> str | None:
        """Why this configuration cannot run on CUDA, or None."""
        c = self.config
        if not c.kernel_draws:
            return "task: the v0 ids draw their episodes on the host (numpy); on device='cuda' use the v1 ids"
        if not _kernel_stepper(c.stepper):
            return f"integrator: {c.stepper.method!r} has no batch kernel (use one of {', '.join(_batch_kinds())})"
        if c.custom_potential is not None:
            return "potential: a custom (Python) potential cannot run on the device"
        return None

    # --- arrays ----------------------------------------------------------------------------------
    def _write_rows(self, row: int, values: np.ndarray) -> None:
        """Write rows ``row``… of ``S`` from host values (both backends)."""
        if self.backend == "cpu":
            self.S[row : row + values.shape[0]] = values
        else:  # those rows alone (contiguous in the row-major array), not the whole batch there and back
            self.S[row : row + values.shape[0]].copy_to_device(np.ascontiguousarray(values, dtype=np.float64))

    def set_clocks(self, steps: np.ndarray) -> None:
        """Set every body's episode clock to ``steps`` (N,) (CPU) and, where the task observes time, its observation
        of it, as a step would have written it (:meth:`observed_time`)."""
        self.K[tr.K_CLOCK] = steps
        t = self.observed_time(np.asarray(steps, dtype=np.float64))
        if t is not None:
            self.OBS[:, -1] = t

    def observed_time(self, steps):
        """The observation's ``time`` entry at the clocks ``steps`` (float64 numpy or torch, any backend) as
        :func:`~flatbody_env.env.transition.observe_clock` computes it; None where the task does not observe time."""
        if not self.config.task.observe_time:
            return None
        return steps.clip(max=tr.MAX_OBSERVED_STEPS) / MAX_EPISODE_STEPS

    def host(self, name: str) -> np.ndarray:
        """A host copy of array ``name`` (``S``, ``K``, ``OBS``, ``FINAL``)."""
        a = getattr(self, name)
        return a.copy() if self.backend == "cpu" else a.copy_to_host()

    # --- launches --------------------------------------------------------------------------------
    def _check(self) -> None:
        """Raise the error a launch flagged (``FLAGS``), and clear it."""
        flags = self.FLAGS if self.backend == "cpu" else self.FLAGS.copy_to_host()
        code, body = int(flags[0]), int(flags[1])
        if code == 0:
            return
        if self.backend == "cpu":
            self.FLAGS[:] = 0
        else:
            self.FLAGS.copy_to_device(np.zeros(2, np.int64))
        task = self.config.task
        if code == tr.ERR_ACTION:
            if self.num_envs == 1:
                raise validation.refusal(self.action_field, "be finite numbers in [-1, 1] (the body was not stepped)")
            raise validation.refusal(
                self.action_field,
                f"be finite numbers in [-1, 1] (body {body} was not stepped; the bodies with finite actions were)",
            )
        if code == tr.ERR_NO_TARGET:
            raise ValueError(task.no_target_message)
        if code == tr.ERR_NO_WITNESS:
            raise ValueError(task.no_witness_message)
        raise ValueError(f"initial_noise: body {body}'s start lies outside the domain; lower initial_noise")

    def _reset_launch(self, mask: np.ndarray, mode: int, write_info: bool, stagger: bool) -> None:
        args = (self.S, self.K, self.OBS, self.FINAL, self.FLAGS, *self._dev)
        if self.backend == "cpu":
            tr.cpu("reset_lanes")(mask.astype(np.uint8), mode, int(write_info), int(stagger), *args)
        else:
            blocks, threads = self._cuda._blocks(self.num_envs, self.threads_per_block)
            tr.cuda_kernels()[1][blocks, threads](
                self._put(mask.astype(np.uint8)), mode, int(write_info), int(stagger), *args
            )

    def reset(
        self,
        *,
        seeds=None,
        mask: np.ndarray | None = None,
        options: Mapping[str, Any] | None = None,
        stagger: bool = False,
    ) -> None:
        """Reset the bodies of ``mask`` (all when None): seeds (a list, one per body, or None to continue each body's
        stream), ``options`` (``target``, ``state``: the single env's and the CPU faces'), ``stagger`` (their clocks at
        uniform steps of the episode)."""
        n = self.num_envs
        mask = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        idx = np.flatnonzero(mask)
        self._seed(idx, seeds)
        options = _checked_options(options)
        if self.config.kernel_draws and not options:
            self._reset_launch(mask, tr.RESET_DRAW, True, stagger)
        else:
            self._reset_given(idx, options)
            self._reset_launch(mask, tr.RESET_OBSERVE, True, stagger)
        self._check()
        if self.R is not None:
            self.R = np.eye(3)
        self._add_custom_energy(idx)

    def _seed(self, idx: np.ndarray, seeds) -> None:
        """Each reset body's seed: the given one, or (none given, never seeded) one from fresh entropy."""
        if seeds is None:
            idx = idx[~self.seeded[idx]]
            if idx.size == 0:
                return
            base = int(np.random.SeedSequence().generate_state(1, np.uint64)[0] >> np.uint64(2))
            values = base + idx
        else:
            values = np.array([int(seeds[i]) for i in idx.tolist()], dtype=np.int64)
        if idx.size == 0:
            return
        K = self.K if self.backend == "cpu" else self.K.copy_to_host()
        K[tr.K_SEED, idx] = values
        K[tr.K_EPISODE, idx] = 0
        self.seeded[idx] = True
        if not self.config.kernel_draws:  # the v0 ids: a numpy generator per body (Gymnasium's seeding)
            from gymnasium.utils import seeding

            for i, s in zip(idx.tolist(), values.tolist(), strict=True):
                self.rngs[i] = seeding.np_random(s)[0]
        if self.backend != "cpu":
            self.K.copy_to_device(K)

    def _reset_given(self, idx: np.ndarray, options: Mapping[str, Any]) -> None:
        """The host's part of a reset: the v0 ids' draws, or what ``options`` give (written into ``S``)."""
        c = self.config
        if idx.size == 0:
            return
        if self.backend != "cpu":
            raise ValueError(
                "options: target and state are set on the CPU faces (device='cpu'); on CUDA use reset_mask and stagger"
            )
        if options:
            if "target" in options and c.task.varies_body:
                raise ValueError("options.target: not with a task that draws its body per episode")
            if c.kernel_draws and "state" not in options:  # the target given, the start drawn by the transition
                for i in idx.tolist():
                    target = _target_from(c.task, options["target"], self.body_of(i))
                    self._write_episode(
                        i, Episode(state=self.S[:11, i].copy(), target=target_row(target), ellipse=target)
                    )
                self._reset_launch(np.isin(np.arange(self.num_envs), idx), tr.RESET_START, True, False)
                self._check()
                return
            if c.kernel_draws and "target" not in options:  # the state alone: the seed's episode's target (and body)
                c.check_start(pack(options["state"], validate=False), "options.state")  # before anything is drawn
                self._reset_launch(np.isin(np.arange(self.num_envs), idx), tr.RESET_DRAW, True, False)
                self._check()
            field = "options.state" if "state" in options else "initial_noise"
            for i in idx.tolist():
                ep = self._draw_with_options(i, options)
                c.check_start(ep.state, field)
                self._write_episode(i, ep)
        else:
            self.host_draw(idx)

    def host_draw(self, idx: np.ndarray) -> None:
        """The v0 ids' draws for the bodies ``idx`` from their numpy generators (each draws what a single env reset
        would: the task's :meth:`~flatbody_env.env.task.ReachStationaryEllipse.draw_batch`), written into ``S``;
        ValueError naming ``initial_noise`` for a start outside the domain."""
        c = self.config
        rngs = [self.rngs[i] for i in idx.tolist()]
        if any(r is None for r in rngs):
            from gymnasium.utils import seeding

            for k, i in enumerate(idx.tolist()):
                if rngs[k] is None:
                    rngs[k] = self.rngs[i] = seeding.np_random(None)[0]
        for k in range(0, len(rngs), HOST_DRAW_CHUNK):  # bounded memory: the reversed runs of a chunk at a time
            chunk = rngs[k : k + HOST_DRAW_CHUNK]
            episodes = c.task.draw_batch(chunk, c.body, limits=c.limits, control=c.control, simulator=self)
            for i, ep in zip(idx[k : k + HOST_DRAW_CHUNK].tolist(), episodes, strict=True):
                c.check_start(ep.state, "initial_noise")
                self._write_episode(i, ep)

    def _draw_with_options(self, i: int, options: Mapping[str, Any]) -> Episode:
        """The target and/or state that ``options`` give; what they do not give is drawn by the task from the body's
        generator (the v0 ids) or is the target the transition has drawn for the seed's episode (the v1 ids)."""
        c = self.config
        body = self.body_of(i)
        rng = self.rngs[i] or np.random.default_rng()
        if "target" in options:
            target = _target_from(c.task, options["target"], body)
        elif c.kernel_draws:
            target = None
        else:
            target = c.task.sample_target(rng, body, limits=c.limits, control=c.control)
        if "state" in options:
            y = pack(options["state"], validate=False)
        else:
            y = c.task.start_near(rng, target, c.control, body=body)
        row = self.S[tr.TG0 : tr.TG0 + 6, i].copy() if target is None else target_row(target)
        return Episode(state=y, target=row, ellipse=target)

    def _write_episode(self, i: int, ep: Episode) -> None:
        self.S[tr.Y0 : tr.Y0 + 11, i] = ep.state
        self.S[tr.TG0 : tr.TG0 + 6, i] = ep.target
        body = ep.body if ep.body is not None else (self.config.body if not self.config.task.varies_body else None)
        if body is not None:
            self.S[tr.P0 : tr.P0 + 9, i] = body.kernel_params()
        self.S[tr.W0 : tr.W0 + 9, i] = 0.0 if ep.witness_params is None else ep.witness_params
        self.targets[i] = ep.ellipse

    def body_of(self, i: int) -> Body:
        """Body ``i``'s :class:`~flatbody_env.physics.body.Body` (the configuration's unless the task draws one)."""
        if not self.config.task.varies_body:
            return self.config.body
        from flatbody_env.env.any_body import body_from_constants

        P = self.host("S")[tr.P0 : tr.P0 + 9, i]
        return body_from_constants(P[list(tr.P_CONSTANTS)])

    def step(self, A) -> None:
        """One env step of every body with actions ``A`` (N, n) (float32 or float64, on the core's backend)."""
        if self._fast is not None:  # one compiled call: the per-body loop with the transition's own draws
            self._fast[0](A, *self._fast[1])
            if self.FLAGS[0]:
                self._check()
            return
        c = self.config
        if self.backend == "cuda":
            blocks, threads = self._cuda._blocks(self.num_envs, self.threads_per_block)
            tr.cuda_kernels()[0][blocks, threads](A, self.S, self.K, self.OBS, self.FINAL, self.FLAGS, *self._dev)
            self._check()
            return
        host = not c.kernel_draws
        if host and self.autoreset == "next":  # the v0 ids: the host draws the pending resets before the launch
            pending = np.flatnonzero(self.K[tr.K_PENDING])
            if pending.size:
                self.host_draw(pending)
        if self._mode == "lanes":
            tr.cpu("step_lanes")(A, self.S, self.K, self.OBS, self.FINAL, self.FLAGS, *self._dev)
        else:
            if not np.isfinite(A).all():  # before any body moves (the per-body loop checks each body itself)
                raise validation.refusal(self.action_field, "be finite numbers in [-1, 1] (no body was stepped)")
            tr.cpu("controls_lanes")(A, self.S, self.K, self.xcfg, self._AC, self._U)
            Y = self.S[tr.Y0 : tr.Y0 + 11]
            st = self._stepper
            if self._mode == "fused":  # a body drawn per episode: the fused step takes each body's own parameters
                bodies = self.S[tr.P0 : tr.P0 + 9] if c.task.varies_body else None
                st.advance_batch(Y, self._U, c.dt, self._OUT, self._STATUS, self._NFEV, bodies)
            else:
                if c.task.varies_body:  # one body (the single env) drawn per episode: the stepper follows its body
                    P = self.S[tr.P0 : tr.P0 + 9, 0]
                    if self._seam is None or not np.array_equal(self._seam[0], P):
                        self._seam = (P.copy(), st.with_body(self.body_of(0)))
                    st = self._seam[1]
                if self.R is not None:
                    counters = np.zeros(3, np.int64)
                    out = np.empty(11)
                    Rnew = np.empty((3, 3))
                    self._STATUS[0] = st.advance(
                        Y[:, 0].copy(), self._U[:, 0].copy(), c.dt, out, counters, self.R, Rnew
                    )
                    self._OUT[:, 0] = out
                    self._NFEV[0] = counters[0]
                else:
                    st.advance_batch(Y, self._U, c.dt, self._OUT, self._STATUS, self._NFEV)
            tr.cpu("finish_lanes")(
                self._AC,
                self._OUT,
                self._STATUS,
                self._NFEV,
                self.S,
                self.K,
                self.OBS,
                self.FINAL,
                self.FLAGS,
                *self._dev,
                self._lanes,
            )
            if (
                self.R is not None
                and self.K[tr.K_STATUS, 0] == 0
                and self.K[tr.K_CODE, 0] in (0, tr.CODE_LEFT_TOLERANCE)
            ):
                self.R = Rnew
        self._check()
        if host and self.autoreset == "same":
            ended = np.flatnonzero(self.K[tr.K_HOST])
            if ended.size:
                self.host_draw(ended)
                self._reset_launch(self.K[tr.K_HOST] != 0, tr.RESET_OBSERVE, False, False)
                self._check()
        self._add_custom_energy(None)

    def _add_custom_energy(self, idx) -> None:
        """A custom potential's part of H, which the kernels leave out of the energy row (they know the built-in
        potentials only)."""
        pot = self.config.custom_potential
        if pot is None:
            return
        cols = range(self.num_envs) if idx is None else idx.tolist()
        for i in cols:
            y = self.S[:11, i]
            self.S[tr.R_ENERGY, i] += float(pot.value(float(y[7]), float(y[8]), float(y[9])))

    # --- simulation without episodes (the witness of the v0 ids, planners) -----------------------
    def set_bodies(self, Y: np.ndarray, TG: np.ndarray, P: np.ndarray | None = None) -> None:
        """Put every body at the state ``Y`` (11, N) with the target ``TG`` (6, N) (λ*, μ*, ϱ*, s3*, p_θ*, sign) and,
        when given, the body's kernel parameters ``P`` (9, N); clocks and ends cleared, nothing drawn or observed (CPU).
        A planner then steps the batch from there (:mod:`agents.planner`)."""
        if self.backend != "cpu":
            raise ValueError("device: set_bodies runs on the CPU batch")
        self.S[tr.Y0 : tr.Y0 + 11] = Y
        self.S[tr.TG0 : tr.TG0 + 6] = TG
        if P is not None:
            self.S[tr.P0 : tr.P0 + 9] = P
            if self.config.task.body_observation_names:  # the observed constants, as a reset writes them
                self.OBS[:, 16:21] = P[list(tr.P_CONSTANTS)].T
        self.S[tr.R_RETURN] = 0.0
        self.K[[tr.K_CLOCK, tr.K_TERMINATED, tr.K_TRUNCATED, tr.K_PENDING, tr.K_HOST, tr.K_EP_DONE]] = 0
        self.set_clocks(self.K[tr.K_CLOCK])
        self._seam = None

    def rollout(self, Y: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance N bodies from the states ``Y`` (11, N) under the normalised actions ``actions`` (steps, N, n) with
        this
        configuration's integrator and body; returns the final states (11, N) and whether each body stayed inside the
        domain without an integrator failure (N,) bool (a failed body keeps its last valid state). The v0 witnessed
        starts use it (:meth:`~flatbody_env.env.witness.ReachWithWitness.draw_batch`)."""
        from flatbody_env.env import compiled

        c = self.config
        Y = np.array(Y, dtype=np.float64, order="C")
        n = Y.shape[1]
        actions = np.asarray(actions, dtype=np.float64)
        if actions.ndim != 3 or actions.shape[1] != n or actions.shape[2] != c.n_act:
            raise ValueError(f"actions: expected shape (steps, {n}, {c.n_act}), got {actions.shape}")
        out, status, nfev, codes = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
        if not np.isfinite(actions).all():
            raise validation.refusal("actions", "be finite numbers")
        ok = np.ones(n, dtype=bool)
        for k in range(actions.shape[0]):
            U = np.ascontiguousarray(c.controls(actions[k])[1].T)
            self._stepper.advance_batch(Y, U, c.dt, out, status, nfev)
            compiled.domain_codes(out, c.kcfg, codes)
            ok &= (status == 0) & (codes == 0)
            np.copyto(Y, out, where=ok)
        return Y, ok


# --------------------------------------------------------------------------------------------- helpers
def _batch_kinds() -> dict:
    from flatbody_env.integrators.batch_solve import KIND

    return KIND


def _kernel_stepper(st) -> bool:
    """Whether the transition's per-body integrator runs this stepper's method (compiled, a batch kind, no R)."""
    return (
        bool(getattr(st, "compiled", False))
        and not getattr(st, "carries_rotation", False)
        and st.method in _batch_kinds()
    )


def _outside_the_table(c: EnvConfig) -> ValueError:
    """The refusal of a v1 configuration whose targets the shipped settling-rate table does not cover, naming the
    keywords that took it outside (the table's own ranges where they are the target ranges)."""
    from flatbody_env.env.targets import shipped_table

    table, task = shipped_table(), c.task
    names = (
        table.mismatch(c.body, c.limits, c.control, task.target_lambda, task.target_aspect) if table is not None else ()
    ) or ("min_settling_rate",)
    ranges = ""
    if table is not None and "target_lambda" in names:
        ranges += f"; its λ* in [{table.lambdas[0]:g}, {table.lambdas[-1]:g}], got {tuple(task.target_lambda)}"
    if table is not None and "target_aspect" in names:
        ranges += f"; its aspect in [{table.aspects[0]:g}, {table.aspects[-1]:g}], got {tuple(task.target_aspect)}"
    return ValueError(
        f"{', '.join(names)}: the v1 resets decide reachability by the shipped settling-rate table, which holds the "
        f"default body, limits and target ranges only{ranges}; with these settings pass min_settling_rate=0"
    )


def _as_task(task: str | ReachStationaryEllipse, task_kwargs: Mapping[str, Any]) -> ReachStationaryEllipse:
    """The task of ``task=`` (a name of :data:`~flatbody_env.env.registration.TASK_CLASSES` with its fields in
    ``task_kwargs``, or a task instance)."""
    if isinstance(task, ReachStationaryEllipse):
        if task_kwargs:
            raise ValueError(
                f"{sorted(task_kwargs)[0]}: give the task's fields to its constructor, not beside a task instance"
            )
        return task
    validation.requirement(
        "task",
        task,
        isinstance(task, str) and task in TASK_CLASSES,
        f"be one of {', '.join(TASK_CLASSES)} or a task instance",
    )
    import importlib

    module, name = TASK_CLASSES[task].split(":")
    cls = getattr(importlib.import_module(module), name)
    import inspect

    params = inspect.signature(cls).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        unknown = sorted(str(k) for k in task_kwargs if k not in params)
        if unknown:
            hint = (
                " (the episode length is gym.make's max_episode_steps, a positive integer, or the vector envs' own)"
                if unknown[0] == "max_episode_steps"
                else ""
            )
            raise ValueError(
                f"{unknown[0][:60]}: not a keyword of FlatBodyEnv or of task {task!r}{hint}; allowed task fields: "
                + ", ".join(
                    k for k, p in params.items() if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD
                )
            )
    try:
        return cls(**task_kwargs)
    except TypeError as exc:  # a keyword the signature above did not catch: name it
        raise ValueError(f"task: {exc}") from None


def _as_body(body: Body | Mapping[str, Any] | None) -> Body:
    if body is None:
        return default_body()
    if isinstance(body, Body):
        return body
    if isinstance(body, Mapping):
        return Body.from_dict(body, where="body")
    raise ValueError(f"body: expected a Body or a dict with params/potential/thickness, got {type(body).__name__}")


def _checked_options(options: Any) -> dict[str, Any]:
    """``reset(options=...)`` validated before use: types, finite numbers within the documented
    ranges (:mod:`flatbody_env.physics.validation`); ``ValueError`` naming ``options.…``."""
    v = validation
    if options is None:
        return {}
    options = dict(v.mapping("options", options))
    if not options:
        return {}
    v.keys("options", options, ("target", "state"))
    target = options.get("target")
    if target is not None and not isinstance(target, StationaryEllipse):
        target = v.mapping("options.target", target)
        v.keys("options.target", target, ("lambda", "mu", "branch", "sign", "rho", "s3", "p_theta"), ("lambda", "mu"))
        checked = {
            k: v.number(f"options.target.{k}", target[k], low=v.STRETCH_RANGE[0], high=v.STRETCH_RANGE[1])
            for k in ("lambda", "mu")
        }
        v.requirement("options.target.mu", checked["mu"], checked["mu"] != checked["lambda"], "differ from lambda")
        for k in ("rho", "s3", "p_theta"):  # a target record's own values: checked, then derived from the shape
            if k in target:
                bound = v.STRETCH_RANGE if k == "rho" else (-v.MOMENTUM_MAX, v.MOMENTUM_MAX)
                v.number(f"options.target.{k}", target[k], low=bound[0], high=bound[1])
        if "branch" in target:
            checked["branch"] = v.string("options.target.branch", target["branch"], choices=("rotation", "circulation"))
        if "sign" in target:
            checked["sign"] = v.number("options.target.sign", target["sign"], low=-1.0, high=1.0)
            v.requirement("options.target.sign", checked["sign"], checked["sign"] in (-1.0, 1.0), "be +1 or -1")
        options["target"] = checked
    if "state" in options:
        options["state"] = v.mapping("options.state", options["state"])
        try:
            validate_state(options["state"], where="options.state")
        except ValueError as exc:
            raise ValueError(str(exc)) from None
    return options


def _target_from(task: ReachStationaryEllipse, spec: Any, body: Body) -> StationaryEllipse:
    """The task's target of ``reset(options={"target": spec})`` (``spec`` as :func:`_checked_options` left it: a
    :class:`~flatbody_env.physics.equilibria.StationaryEllipse`, or ``lambda``, ``mu`` and optionally ``branch``,
    ``sign``); a shape without a stationary ellipse (or one whose ellipse cannot be computed) is a ``ValueError``
    naming ``options.target``."""
    if isinstance(spec, StationaryEllipse):
        return spec
    branch, sign = spec.get("branch", task.target_branch), float(spec.get("sign", 1.0))
    try:
        return stationary_from_shape(body, spec["lambda"], spec["mu"], branch=branch, sign=sign)
    except ValueError as exc:
        head, sep, rest = str(exc).partition(": ")
        raise ValueError(f"options.target: {rest if sep and head == 'lambda, mu' else exc}") from None


def target_of(core: EnvCore, i: int) -> StationaryEllipse:
    """Body ``i``'s target as a full record (built from the target's shape where the draw kept only its row)."""
    t = core.targets[i]
    if t is None:
        tg = core.host("S")[tr.TG0 : tr.TG0 + 6, i]
        t = stationary_from_shape(
            core.body_of(i), float(tg[0]), float(tg[1]), branch=core.config.task.target_branch, sign=float(tg[5])
        )
        core.targets[i] = t
    return t


__all__ = ["DEFAULT_INTEGRATOR", "DEFAULT_TOLERANCE", "EnvConfig", "EnvCore", "configure", "end_reason", "target_of"]
