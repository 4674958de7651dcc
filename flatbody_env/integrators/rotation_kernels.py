"""The compiled two-polar methods carrying the orientation R: the same stepping code on z = (y, vec(R)).

Rendering and recording need R(t) (Ṙ = R W(ω), eq. (25) of [1]). The compiled methods of
:mod:`.twopolar_kernels` step the eleven paper variables only; this module compiles *the same
stepping source* a second time (:func:`~flatbody_env.integrators.jit.retarget`, which re-binds recursively) on
the 20-entry state z = (y, R row by row) of :data:`flatbody_env.physics.equations.ROTATED_STATE_SIZE`,
so no loop, coefficient or step-control rule is restated:

* **DOP853-numba**: ``N`` re-bound to 20 and the right-hand side to
  :func:`~flatbody_env.physics.equations.rhs_rotation_kernel`, so R is advanced by the same 12
  stages as y. The error norm (``_dop853_error``) keeps N = 11 and the first-step guess is given
  the paper entries only (:func:`dop853_initial_step_paper`): the step sizes are chosen on the
  paper state alone, exactly as without R. The paper state is therefore
  **bit for bit** the one the method computes without R (tested), and R rides on those steps with
  the method's order.
* **RK4**: the same stages on z (R is a passenger of the classical RK4 step).
* **Splittings** (Strang, Suzuki-4, Yoshida-4): every piece stays an exact flow. R does not move
  under T_q, V and the torque; under H1, H2, H3 the angular velocity ∂H_i/∂s is frozen along the
  piece's flow (ω1 e1, ω2 e2, ω3 e3), so R's exact flow is R exp(h W(ω_i e_i))
  (:func:`~flatbody_env.physics.equations.turn_rotation_kernel`), applied right after the piece
  moves s. R stays a rotation to round-off.

Kernels (arrays C-contiguous float64; z, zout (20,)):

    status = env_step_R(kind, coeffs, z, u, P, dt, h, rtol, atol, energy_tol, zout, counters)
    status = dop853_solve_R(z0, times, u, P, rtol, atol, energy_tol, Z, counters, fail)      # Z (20, n)
    status = fixed_solve_R(kind, coeffs, z0, times, u, P, h, energy_tol, Z, counters, fail)

with the arguments of :mod:`.twopolar_kernels`. :func:`env_step_with_rotation` gives a method's env
step (:data:`ENV_STEP_WITH_ROTATION` maps the names of :data:`~.specs.ROTATION_METHODS` to them).

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
"""

from __future__ import annotations

import functools

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.jit import njit, retarget, rhs_rotation_kernel, turn_rotation_kernel
from flatbody_env.integrators.specs import BY_NAME, ROTATION_METHODS
from flatbody_env.physics.equations import ROTATED_STATE_SIZE

_NZ = ROTATED_STATE_SIZE


# ---------------------------------------------------------------------------------- the splitting's R flows
def flow_h1_with_rotation(y, h, P, tmp, vel, force):
    """The H1 piece (s rotated by ω1 h) and R's exact flow R exp(h W(ω1 e1)); ω1 = vel[0] as frozen by the piece."""
    _flow_h1(y, h, P, tmp, vel, force)
    turn_rotation_kernel(y, 0, h * vel[0])


def flow_h2_with_rotation(y, h, P, tmp, vel, force):
    """The H2 piece and R exp(h W(ω2 e2))."""
    _flow_h2(y, h, P, tmp, vel, force)
    turn_rotation_kernel(y, 1, h * vel[1])


def flow_h3_with_rotation(y, h, P, tmp, vel, force):
    """The H3 piece and R exp(h W(ω3 e3)); returns the piece's chart turn."""
    turn = _flow_h3(y, h, P, tmp, vel, force)
    turn_rotation_kernel(y, 2, h * vel[2])
    return turn


def dop853_initial_step_paper(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, counters):
    """DOP853's first-step guess from the paper entries of z (scipy's rule sees y only, as without R)."""
    return dop853_initial_step(y[:11], f[:11], t0, t_bound, u, P, rtol, atol, vel, force, work, counters)


def dop853_initial_step_paper_into(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, y1, counters):
    """:func:`dop853_initial_step_paper` with its second work array passed in."""
    return dop853_initial_step_into(y[:11], f[:11], t0, t_bound, u, P, rtol, atol, vel, force, work, y1[:11], counters)


_flow_h1 = _tk._flow_h1
_flow_h2 = _tk._flow_h2
_flow_h3 = _tk._flow_h3
dop853_initial_step = _tk.dop853_initial_step
dop853_initial_step_into = _tk.dop853_initial_step_into

# the stepping code re-bound, recursively, to z: N = 20 and the right-hand side carrying R; the error
# norm and the first-step guess keep to the paper entries, the splitting's pieces turn R by their exact flows
_ON_Z = dict(
    N=_NZ,
    rhs_kernel=rhs_rotation_kernel,
    _dop853_error=_tk._dop853_error,
    _masked_rates=_tk._masked_rates,
    dop853_initial_step=njit(dop853_initial_step_paper),
    dop853_initial_step_into=njit(dop853_initial_step_paper_into),
    _flow_h1=njit(flow_h1_with_rotation),
    _flow_h2=njit(flow_h2_with_rotation),
    _flow_h3=njit(flow_h3_with_rotation),
)
dop853_solve_R = retarget(_tk.dop853_solve, **_ON_Z)
fixed_solve_R = retarget(_tk.fixed_solve, **_ON_Z)
env_step_R = retarget(_tk.env_step, **_ON_Z)
""":func:`~.twopolar_kernels.env_step` on z = (y, vec(R)): ``(kind, coeffs, z, u, P, dt, h, rtol, atol, energy_tol, zout, counters) -> status``."""


def env_step_with_rotation(spec):
    """A method's compiled env step on z = (y, vec(R)) (its row of the method table, ``spec.carries_R``):
    ``(z, u, P, dt, h, rtol, atol, energy_tol, zout, counters) -> status``, :data:`env_step_R` bound to the method's
    (kind, coefficients)."""
    return functools.partial(env_step_R, spec.code, spec.coeffs)


ENV_STEP_WITH_ROTATION = {name: env_step_with_rotation(BY_NAME[name]) for name in ROTATION_METHODS}
"""Method name → :func:`env_step_with_rotation` (the methods of :data:`~.specs.ROTATION_METHODS`)."""

__all__ = [
    "ENV_STEP_WITH_ROTATION",
    "dop853_solve_R",
    "env_step_R",
    "env_step_with_rotation",
    "fixed_solve_R",
    "flow_h1_with_rotation",
    "flow_h2_with_rotation",
    "flow_h3_with_rotation",
]
