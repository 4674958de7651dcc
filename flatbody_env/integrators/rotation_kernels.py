"""The compiled two-polar methods carrying the orientation R: the same stepping code on z = (y, vec(R)).

Rendering and recording need R(t) (Ṙ = R W(ω), eq. (25) of [1]). The compiled methods of
:mod:`.twopolar_kernels` step the eleven paper variables only; this module compiles *the same
stepping source* a second time (:func:`~flatbody_env.integrators.jit.jit_copy` with ``variant``) on
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

    status = <method>_env_step_R(z, u, P, dt, h, rtol, atol, energy_tol, zout, counters)
    status = dop853_solve_R(z0, times, u, P, rtol, atol, energy_tol, Z, counters, fail)      # Z (20, n)
    status = fixed_solve_R(kind, coeffs, z0, times, u, P, h, energy_tol, Z, counters, fail)

with the arguments of :mod:`.twopolar_kernels`. :data:`ENV_STEP_WITH_ROTATION` maps a method name
to its env step.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.jit import jit_copy, rhs_rotation_kernel, turn_rotation_kernel
from flatbody_env.physics import equations as _equations
from flatbody_env.physics.equations import ROTATED_STATE_SIZE

def _source_tag() -> str:
    """A short hash of the sources the copies below are built from besides their own file.

    numba's cache invalidates a function when *its* source file changes, not when a callee does;
    the copies live under :mod:`.twopolar_kernels`' file but call this module's and the physics
    layer's kernels, so their cache name carries this tag and an edit of either gives new entries.
    """
    digest = hashlib.sha256()
    for path in (Path(__file__), Path(_equations.__file__)):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:10]


_V = f"with_R_{_source_tag()}"
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

# ---------------------------------------------------------------------------------- DOP853
_dop853_stages_R = jit_copy(_tk._dop853_stages, variant=_V, N=_NZ, rhs_kernel=rhs_rotation_kernel)
_dop853_advance_R = jit_copy(_tk.dop853_advance, variant=_V, N=_NZ, _dop853_stages=_dop853_stages_R)
_initial_step_R = jit_copy(dop853_initial_step_paper, variant=_V)
_dop853_env_R = jit_copy(_tk._dop853_env, variant=_V, N=_NZ, rhs_kernel=rhs_rotation_kernel, dop853_advance=_dop853_advance_R,
                         dop853_initial_step=_initial_step_R)
dop853_env_step_R = jit_copy(_tk.dop853_env_step_counted, variant=_V, N=_NZ, _dop853_env=_dop853_env_R)
_dop853_solve_into_R = jit_copy(_tk.dop853_solve_into, variant=_V, N=_NZ, rhs_kernel=rhs_rotation_kernel, dop853_advance=_dop853_advance_R,
                                dop853_initial_step_into=jit_copy(dop853_initial_step_paper_into, variant=_V))
dop853_solve_R = jit_copy(_tk.dop853_solve, variant=_V, N=_NZ, dop853_solve_into=_dop853_solve_into_R)

# ---------------------------------------------------------------------------------- RK4 and the splittings
_rk4_step_R = jit_copy(_tk._rk4_step, variant=_V, N=_NZ, rhs_kernel=rhs_rotation_kernel)
_rk4_advance_R = jit_copy(_tk._rk4_advance, variant=_V, _rk4_step=_rk4_step_R)
_flow_h1_R = jit_copy(flow_h1_with_rotation, variant=_V, _flow_h1=_tk._flow_h1)
_flow_h2_R = jit_copy(flow_h2_with_rotation, variant=_V, _flow_h2=_tk._flow_h2)
_flow_h3_R = jit_copy(flow_h3_with_rotation, variant=_V, _flow_h3=_tk._flow_h3)
_strang_step_R = jit_copy(_tk.strang_step, variant=_V, _flow_h1=_flow_h1_R, _flow_h2=_flow_h2_R, _flow_h3=_flow_h3_R)
_split_advance_R = jit_copy(_tk._split_advance, variant=_V, strang_step=_strang_step_R)
_fixed_advance_R = jit_copy(_tk._fixed_advance, variant=_V, _rk4_advance=_rk4_advance_R, _split_advance=_split_advance_R)
_fixed_env_R = jit_copy(_tk._fixed_env, variant=_V, N=_NZ, _fixed_advance=_fixed_advance_R)
fixed_solve_R = jit_copy(_tk.fixed_solve, variant=_V, N=_NZ,
                         fixed_solve_into=jit_copy(_tk.fixed_solve_into, variant=_V, N=_NZ, _fixed_advance=_fixed_advance_R))
rk4_env_step_R = jit_copy(_tk.rk4_env_step_counted, variant=_V, N=_NZ, _fixed_env=_fixed_env_R)
strang_env_step_R = jit_copy(_tk.strang_env_step_counted, variant=_V, N=_NZ, _fixed_env=_fixed_env_R)
suzuki4_env_step_R = jit_copy(_tk.suzuki4_env_step_counted, variant=_V, N=_NZ, _fixed_env=_fixed_env_R)
yoshida4_env_step_R = jit_copy(_tk.yoshida4_env_step_counted, variant=_V, N=_NZ, _fixed_env=_fixed_env_R)

ENV_STEP_WITH_ROTATION = {
    "DOP853-numba": dop853_env_step_R,
    "RK4": rk4_env_step_R,
    "splitting-strang": strang_env_step_R,
    "splitting-suzuki4": suzuki4_env_step_R,
    "splitting-yoshida4": yoshida4_env_step_R,
}
"""Method name → its compiled env step on z = (y, vec(R)): ``(z, u, P, dt, h, rtol, atol, energy_tol, zout, counters) -> status``."""

__all__ = ["ENV_STEP_WITH_ROTATION", "dop853_env_step_R", "dop853_solve_R", "fixed_solve_R", "flow_h1_with_rotation",
           "flow_h2_with_rotation", "flow_h3_with_rotation", "rk4_env_step_R", "strang_env_step_R", "suzuki4_env_step_R",
           "yoshida4_env_step_R"]
