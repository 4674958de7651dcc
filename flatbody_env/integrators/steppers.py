"""The environment-facing step API: one integrator step from a raw status, for one body or N.

:func:`make_env_step` is the seam an environment steps through. It returns

* a :class:`CompiledEnvStep` when the method table marks the method for it (``spec.env``,
  :data:`flatbody_env.integrators.specs.ENV_METHODS`: the two-polar chart's compiled methods): one
  compiled call per env step (and one per batch of N), no Python per sub-step. For a method marked
  ``spec.fused_batch`` (``DOP853-numba``) with the first step guessed as dt (the env's default) and J1 = J2 the
  batch runs the fused SIMD structure-of-arrays step of :mod:`.batch_kernels` (bit for bit the scalar kernel's
  result, faster per body: the figures of ``flatbody bench env`` and where a body-step goes, docs/env.md);
* a :class:`CompiledRotationEnvStep` for the same methods when R must be carried (rendering,
  recording): the same compiled stepping code on z = (y, vec(R)) (:mod:`.rotation_kernels`), the
  paper state bit for bit the one without R;
* a :class:`GenericEnvStep` otherwise: one :meth:`Method.integrate` call over [0, dt] with the
  controls held constant (a fresh solver per step, so an adaptive method never carries its step
  history across an action change), for any registered method, with R when asked.

The method is looked up once, by whoever has its name (the environment's configuration), and the seam is given the
object (a name is accepted too); its refusals of the body and settings are its declared
:meth:`~flatbody_env.integrators.base.Method.check`, called here before a stepper is built.

Both have the same interface, so the environment has one step path::

    status = step.advance(y, u, dt, out, counters, R, R_out)   # 0 = success
    step.advance_batch(Y, U, dt, OUT, STATUS, NFEV)             # structure-of-arrays, in place
    step.advance_batch(Y, U, dt, OUT, STATUS, NFEV, P)          # each body its own (9, N): where steps_bodies
    step.describe(status)                                       # "kind: reason" of a failure
    step.with_body(body)                                        # the same stepper for another body
    step.own()                                                  # the same, with work arrays of its own

* ``y``, ``out`` (11,) paper states (:mod:`flatbody_env.physics.state`); ``u`` (4,) the controls
  (τ1, τ2, τ3, f_ϱ); ``counters`` (3,) int64 accumulates [nfev, steps, rejected steps];
  ``R`` / ``R_out`` (3, 3) the orientation before / after (only when :attr:`carries_rotation`).
* ``Y``, ``OUT`` (11, N), ``U`` (4, N), ``STATUS`` and ``NFEV`` (N,) int64.
* ``status``: :data:`flatbody_env.integrators.failure.KINDS` index (0 = success). On failure
  ``out`` holds no physics; the caller keeps the old state.
* ``own()``: each env core steps through its own copy (a vector env's cores step in threads at once, and the fused
  batch step writes its work arrays in place); the compiled code is shared.

:attr:`method` names the method that really runs and :attr:`compiled` whether it runs compiled
(the environment then uses its compiled bookkeeping too).
"""

from __future__ import annotations

import copy

import numpy as np

from flatbody_env.integrators.base import IntegrationError, Method, Tolerances, get_method
from flatbody_env.integrators.failure import KINDS, failure_reason
from flatbody_env.physics.body import Body

_OTHER_FAILURE = len(KINDS)
"""Status of a failure whose kind is not one of :data:`KINDS` (e.g. a scipy solver's own message)."""


def _method(method: Method | str) -> Method:
    """A registered method, or the one of that name (``ValueError`` for an unknown name)."""
    return get_method(method) if isinstance(method, str) else method


class CompiledEnvStep:
    """A method's compiled environment stepper behind the seam (module docstring); picklable."""

    compiled = True
    carries_rotation = False

    def __init__(self, method: Method | str, body: Body, tol: Tolerances, *, first_step: float = 0.0) -> None:
        from flatbody_env.integrators.compiled_methods import kernel_params

        meth = _method(method)
        self.spec = meth.spec
        self.method = meth.info.name
        self.P = kernel_params(body)
        fixed = not meth.info.adaptive
        # fixed-step methods: the largest sub-step; DOP853: the first step guess (0 = automatic)
        self.h = float(tol.step) if fixed else float(first_step)
        self.rtol = float(tol.rtol)
        self.atol = float(tol.atol)
        self.energy_tol = float(tol.energy_tol)
        self.max_nfev = int(tol.max_nfev)  # each body's budget of RHS evaluations per env step in a batch (DOP853)
        self._load()

    def _load(self) -> None:
        from flatbody_env.integrators.compiled_methods import env_stepper

        st = env_stepper(self.spec)
        self._step = st.step_counted
        self._batch = st.batch_counted
        self._fused = None
        if self.spec.fused_batch and self.h > 0.0 and self.P[0] == self.P[1]:
            from flatbody_env.integrators.batch_kernels import DOP853Batch

            self._fused = DOP853Batch(1)  # the fused structure-of-arrays step (first step = dt), sized on first use

    def __getstate__(self):
        state = dict(self.__dict__)
        del state["_step"], state["_batch"], state["_fused"]
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._load()

    def with_body(self, body: Body) -> CompiledEnvStep:
        """The same stepper for another body (its kernel parameters; the compiled code is shared)."""
        if not body.compiled:
            raise ValueError("body: a compiled stepper needs a built-in potential")
        other = copy.copy(self)
        other.P = np.array(body.kernel_params(), dtype=np.float64)
        if self._fused is not None and other.P[0] != other.P[1]:
            other._fused = None
        return other

    def own(self) -> CompiledEnvStep:
        """The same stepper with work arrays of its own (the compiled code shared): one per thread that steps a batch,
        since the fused step writes its work arrays in place."""
        other = copy.copy(self)
        if self._fused is not None:
            from flatbody_env.integrators.batch_kernels import DOP853Batch

            other._fused = DOP853Batch(1)
        return other

    def advance(self, y, u, dt, out, counters, R=None, R_out=None) -> int:
        return self._step(y, u, self.P, dt, self.h, self.rtol, self.atol, self.energy_tol, out, counters)

    @property
    def steps_bodies(self) -> bool:
        """Whether :meth:`advance_batch` takes each body's parameters (``P``): the fused DOP853 step."""
        return self._fused is not None

    def advance_batch(self, Y, U, dt, OUT, STATUS, NFEV, P=None) -> None:
        if P is not None:  # a batch of bodies, each its own (J1 = J2 in every lane; checked by the fused step)
            if self._fused is None or self.h != dt:
                raise ValueError("P: a batch of bodies steps through the fused DOP853 step only")
            self._fused(Y, U, P, dt, self.rtol, self.atol, self.energy_tol, OUT, STATUS, NFEV, self.max_nfev)
            return
        if self._fused is not None and self.h == dt:
            self._fused(Y, U, self.P, dt, self.rtol, self.atol, self.energy_tol, OUT, STATUS, NFEV, self.max_nfev)
            return
        self._batch(Y, U, self.P, dt, self.h, self.rtol, self.atol, self.energy_tol, OUT, STATUS, NFEV, self.max_nfev)

    def describe(self, status: int, lane: int | None = None) -> str:
        return f"{KINDS[status]}: {failure_reason(status)}"


class GenericEnvStep:
    """One :meth:`Method.integrate` call per env step (module docstring); picklable."""

    compiled = False

    def __init__(self, method: Method | str, body: Body, tol: Tolerances, *, with_rotation: bool = False) -> None:
        self._meth = _method(method)
        self.method = self._meth.info.name
        self.body = body
        self.tol = tol
        self.carries_rotation = bool(with_rotation)
        self._last = ""
        self._lane_reasons: dict[int, str] = {}

    def with_body(self, body: Body) -> GenericEnvStep:
        """The same stepper for another body."""
        other = copy.copy(self)
        other.body = body
        other._lane_reasons = {}
        return other

    def own(self) -> GenericEnvStep:
        """The same stepper with its failure record of its own (one per env core)."""
        other = copy.copy(self)
        other._lane_reasons = {}
        return other

    def _run(self, y, u, dt, R):
        try:
            sol = self._meth.integrate(
                self.body, y, np.array([0.0, dt]), tol=self.tol, u=u, R0=R, with_rotation=self.carries_rotation
            )
        except IntegrationError as exc:
            status = KINDS.index(exc.kind) if exc.kind in KINDS and exc.kind != "ok" else _OTHER_FAILURE
            return status, f"{exc.kind}: {exc.reason}", None
        return 0, "", sol

    def advance(self, y, u, dt, out, counters, R=None, R_out=None) -> int:
        status, message, sol = self._run(y, u, dt, R)
        if status:
            self._last = message
            out[:] = y
            return status
        out[:] = sol.Y[:, -1]
        counters[0] += sol.nfev
        counters[1] += int(sol.stats.get("steps", 0))
        if R_out is not None and sol.rotation is not None:
            R_out[:] = sol.rotation[-1]
        return 0

    def advance_batch(self, Y, U, dt, OUT, STATUS, NFEV) -> None:
        self._lane_reasons = {}
        counters = np.zeros(3, np.int64)
        out = np.empty(Y.shape[0])
        for k in range(Y.shape[1]):
            counters[:] = 0
            STATUS[k] = self.advance(Y[:, k].copy(), U[:, k].copy(), dt, out, counters)
            OUT[:, k] = out
            NFEV[k] = counters[0]
            if STATUS[k]:
                self._lane_reasons[k] = self._last

    def describe(self, status: int, lane: int | None = None) -> str:
        if lane is not None:
            return self._lane_reasons.get(
                lane, f"{KINDS[status] if status < len(KINDS) else 'failure'}: {failure_reason(status)}"
            )
        return self._last


class CompiledRotationEnvStep(CompiledEnvStep):
    """A compiled two-polar method that also carries R (:mod:`.rotation_kernels`): one compiled call per
    env step on z = (y, vec(R)); the paper state is bit for bit the one :class:`CompiledEnvStep` computes.
    ``advance_batch`` (no R) is :class:`CompiledEnvStep`'s."""

    carries_rotation = True

    def _load(self) -> None:
        from flatbody_env.integrators.rotation_kernels import env_step_with_rotation

        super()._load()
        self._step_R = env_step_with_rotation(self.spec)
        self._z = np.empty(20)
        self._zout = np.empty(20)

    def __getstate__(self):
        state = super().__getstate__()
        for key in ("_step_R", "_z", "_zout"):
            state.pop(key, None)
        return state

    def advance(self, y, u, dt, out, counters, R=None, R_out=None) -> int:
        if R is None:
            return super().advance(y, u, dt, out, counters)
        z, zout = self._z, self._zout
        z[:11] = y
        z[11:] = np.ravel(R)
        status = self._step_R(z, u, self.P, dt, self.h, self.rtol, self.atol, self.energy_tol, zout, counters)
        out[:] = zout[:11]
        if R_out is not None:
            R_out[:] = zout[11:].reshape(3, 3)
        return status


def make_env_step(
    method: Method | str, body: Body, tol: Tolerances, *, with_rotation: bool = False, first_step: float = 0.0
) -> CompiledEnvStep | GenericEnvStep:
    """The environment step of ``method``, a registered method (:func:`~.base.get_method`) or its name (module
    docstring).

    With ``with_rotation=True`` the compiled two-polar methods carry R in their own compiled step
    (:class:`CompiledRotationEnvStep`); other methods return R through :meth:`Method.integrate`.
    Raises ValueError for an unknown name or a step setting or body the method refuses (its
    :meth:`~.base.Method.check`). ``first_step`` is DOP853's first step guess (0 = automatic).
    """
    meth = _method(method)
    meth.check(body, tol)
    spec = meth.spec
    if body.compiled and spec is not None and spec.env and (spec.carries_R or not with_rotation):
        return (CompiledRotationEnvStep if with_rotation else CompiledEnvStep)(meth, body, tol, first_step=first_step)
    return GenericEnvStep(meth, body, tol, with_rotation=with_rotation)


__all__ = ["CompiledEnvStep", "CompiledRotationEnvStep", "GenericEnvStep", "make_env_step"]
