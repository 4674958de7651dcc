"""Compiled (numba) integrators of the two-polar equations (eqs. (44)–(49) of [1], docs/physics.md §4 of [2]).

Three families, all built on the physics kernels (jitted copies, :mod:`.jit`):

* ``dop853_*`` — a port of scipy's ``DOP853`` (Hairer's coefficients, taken from
  ``scipy.integrate._ivp.dop853_coefficients``; the same initial-step choice, error norm
  (the 5th/3rd-order blend) and step control: safety 0.9, factors in [0.2, 10], exponent −1/8).
  It steps exactly onto every output time instead of using dense output.
* ``rk4_*`` — the classical fixed-step Runge–Kutta method of order 4; each output interval is
  divided into ⌈Δt/h⌉ equal steps.
* ``split_*`` — the Poisson splitting of docs/physics.md §10 (isotropic J1 = J2), every piece an exact flow.
  With ℋ = T_q + V + H1 + H2 + H3,

  - T_q = (p_λ² + p_μ²)/(2J) + p_ϱ²/(2J3): drift of (λ, μ, ϱ);
  - V (+ the force f_ϱ): kick of (p_λ, p_μ, p_ϱ); it commutes with H1, H2, H3 and the torque;
  - H1 = s1²/(2I1): rotation of (s2, s3) by ω1 h, kicks of p_μ, p_ϱ (docs/physics.md §10);
  - H2 = s2²/(2I2): rotation of (s1, s3) by ω2 h, kicks of p_λ, p_ϱ;
  - H3 = σ₊²/(4J(λ+μ)²) + σ₋²/(4J(λ−μ)²): rotation of (s1, s2) by ω3 h, θ += θ̇ h, kicks of p_λ, p_μ;
  - the torque τ: s += h τ.

  Each piece's rates are read off :func:`flatbody_env.physics.hamiltonian.kinetic_kernel` evaluated on the
  state with the other momenta zeroed (so no formula is restated). Strang's symmetric step is
  T(h/2) τ(h/2) V(h) H1(h/2) H2(h/2) H3(h) H2(h/2) H1(h/2) τ(h/2) T(h/2) (order 2); compositions
  with the coefficient vectors :data:`SUZUKI4` (5 stages) and :data:`YOSHIDA4` (3 stages) give
  order 4. Rotations keep |s|² to round-off and no piece changes p_θ.

Every kernel returns an integer status (:mod:`.failure`): non-finite values, λ, μ, ϱ ≤ 0,
λ − μ changing sign while σ₋ ≠ 0 (chart singularity), step collapse (DOP853), chart
under-resolution (fixed steps that turn θ by more than 1 rad), energy error beyond tolerance
(without controls).

Environment API (one env step, no Python per sub-step; ``P`` = ``Body.kernel_params()`` as a
writable float64 array (9,); arrays C-contiguous float64), one kernel for every method::

    status = env_step(kind, coeffs, y, u, P, dt, h, rtol, atol, energy_tol, out, counters)

with ``(kind, coeffs)`` from the method table (:data:`~.specs.SPECS`: ``spec.code``, ``spec.coeffs``);
y, out (11,); u (4,); ``counters`` (3,) int64 accumulates [nfev, steps, rejected steps]. ``h`` is the
largest sub-step of fixed-step methods and the initial step guess of DOP853 (0: automatic);
rtol/atol are read by DOP853 only; energy_tol = inf switches the energy check off. N bodies:
:func:`~.batch_solve.batch_env_step_serial`.

References
----------
.. [1] V. Kovalchuk and E. E. Rożko, "Classical models of affinely-rigid bodies with 'thickness' in degenerate dimension", arXiv:0902.3573 (2009).
.. [2] ``docs/physics.md`` (the corrected equations and the errata of [1]).
.. [3] E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*, §II.4, II.10.
"""

from __future__ import annotations

import math

import numpy as np
from flatbody_env.integrators.dop853_tableau import ERROR_E3 as _ERROR_E3
from flatbody_env.integrators.dop853_tableau import ERROR_E5 as _ERROR_E5
from flatbody_env.integrators.dop853_tableau import ERROR_J as _ERROR_J
from flatbody_env.integrators.dop853_tableau import STAGE_C as _STAGE_C
from flatbody_env.integrators.dop853_tableau import STAGE_J as _STAGE_J
from flatbody_env.integrators.dop853_tableau import STAGE_L as _STAGE_L

from flatbody_env.integrators.compositions import KAHAN_LI6, STRANG, SUZUKI4, YOSHIDA4  # noqa: F401 (re-exported)
from flatbody_env.integrators.failure import (
    CHART_SINGULARITY,
    DOMAIN,
    ENERGY,
    MAX_STEPS,
    MAX_TURN,
    NON_FINITE,
    OK,
    STEP_COLLAPSE,
    UNDER_RESOLVED,
)
from flatbody_env.integrators.specs import DOP853_KIND
from flatbody_env.integrators.jit import njit, energy_kernel, kinetic_kernel, potential_kernel, rhs_kernel


N = 11
_SAFETY = 0.9
_MIN_FACTOR = 0.2
_MAX_FACTOR = 10.0
_ERROR_EXPONENT = -1.0 / 8.0  # scipy: -1/(error_estimator_order + 1), order 7
DOP853_MAX_STEPS = 50_000_000

# Where a DOP853 run stands when its budget of evaluations stopped it (:func:`dop853_solve_into`'s ``carry``, float64):
CARRY_T = 0
"""The time reached."""
CARRY_H = 1
"""The next step size |h|."""
CARRY_K = 2
"""The output row being integrated to (0: not started; -1: finished, nothing to continue)."""
CARRY_REJECTED = 3
"""1 when the next attempt follows a rejected one."""
CARRY_GAP_SIGN = 4
CARRY_CHECK_GAP = 5
CARRY_H0 = 6
"""H at the start (the energy check)."""
CARRY_COUNTERS = 7
"""The counts so far (nfev, accepted, rejected): three entries."""
CARRY_Y = 10
"""The state y (N entries), then its derivative f (N)."""


def carry_size(n: int = 11) -> int:
    """Entries of a ``carry`` for a state of ``n`` entries (11; 20 with R, :mod:`.rotation_kernels`)."""
    return CARRY_Y + 2 * n


# --------------------------------------------------------------------------------------------- checks
@njit
def _finite(y):
    for i in range(y.size):
        if not math.isfinite(y[i]):
            return False
    return True


@njit
def state_code(finite, lam, mu, rho, gap_sign, check_gap):
    """Status of a state after a step from its values (the one decision; scalars, so that a loop over
    lanes calls it without array arguments): non-finite, domain (λ, μ, ϱ ≤ 0), chart singularity
    (λ − μ changed sign: ``gap_sign`` is its sign at the start, ``check_gap`` False where the chart may cross)."""
    if not finite:
        return NON_FINITE
    if lam <= 0.0 or mu <= 0.0 or rho <= 0.0:
        return DOMAIN
    if check_gap and (lam - mu) * gap_sign <= 0.0:
        return CHART_SINGULARITY
    return OK


@njit
def _state_status(y, gap_sign, check_gap):
    """Status of a state ``y`` (11,) after a step (:func:`state_code`)."""
    return state_code(_finite(y), y[7], y[8], y[9], gap_sign, check_gap)


@njit
def crossable(J1, J2, s3, p_theta, tau3):
    """True when λ = μ is passable in the chart: J1 = J2, σ₋ = s3 − p_θ = 0 and τ3 = 0 (docs/physics.md §7); scalars."""
    return J1 == J2 and s3 == p_theta and tau3 == 0.0


@njit
def may_cross(y, u, P):
    """:func:`crossable` of a state ``y`` (11,), controls ``u`` (4,) and kernel parameters ``P``."""
    return crossable(P[0], P[1], y[2], y[3], u[2])


@njit
def no_control(u):
    for i in range(u.size):
        if u[i] != 0.0:
            return False
    return True


# --------------------------------------------------------------------------------------------- DOP853
@njit
def _rms(x, y, rtol, atol):
    """RMS of x / (atol + |y| rtol) (scipy's scaled norm; the scale is formed on the fly, no work array)."""
    acc = 0.0
    for i in range(x.size):
        r = x[i] / (atol + abs(y[i]) * rtol)
        acc += r * r
    return math.sqrt(acc / x.size)


@njit
def dop853_initial_step_into(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, y1, counters):
    """scipy's ``select_initial_step`` (Hairer–Nørsett–Wanner §II.4) with error order 7.

    Allocates nothing (the CUDA target compiles it as a device function): ``work`` and ``y1``
    (11,) are work space."""
    interval = abs(t_bound - t0)
    if interval == 0.0:
        return 0.0
    d0 = _rms(y, y, rtol, atol)
    d1 = _rms(f, y, rtol, atol)
    if d0 < 1e-5 or d1 < 1e-5:
        h0 = 1e-6
    else:
        h0 = 0.01 * d0 / d1
    h0 = min(h0, interval)
    for i in range(N):
        y1[i] = y[i] + h0 * f[i]
    rhs_kernel(y1, u, P, work, vel, force)
    counters[0] += 1
    for i in range(N):
        y1[i] = work[i] - f[i]
    d2 = _rms(y1, y, rtol, atol) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, interval)


@njit
def dop853_initial_step(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, counters):
    """:func:`dop853_initial_step_into` with its second work array allocated (CPU callers)."""
    return dop853_initial_step_into(y, f, t0, t_bound, u, P, rtol, atol, vel, force, work, np.empty(N), counters)


@njit
def next_up(t):
    """``np.nextafter(t, inf)``, bit for bit, from ``math.frexp``/``math.ldexp`` only (both targets
    compile these; numba's CUDA target has no ``nextafter``)."""
    if t != t or t == math.inf:
        return t
    if t == -math.inf:
        return -1.7976931348623157e308
    if t == 0.0:
        return 5e-324
    m, e = math.frexp(t)  # t = m 2**e, 0.5 <= |m| < 1
    ulp = math.ldexp(1.0, e - 54) if m == -0.5 else math.ldexp(1.0, e - 53)
    up = t + max(ulp, 5e-324)  # subnormals: the spacing is 2**-1074
    return -0.0 if up == 0.0 else up  # from -2**-1074 the next float up is -0.0


@njit
def _dop853_stages(y, f, h, u, P, K, ynew, ytmp, vel, force):
    for i in range(N):
        K[0, i] = f[i]
    # stage s = 1 … 11, then the solution (s = 12, the b_j), each at y + h Σ_j c_sj K_j: the sum over j as one loop over
    # the components per j (the same additions in the same order as one sum per component, which would chain each
    # component's additions); one call of the right-hand side (compiled into this loop), into ynew, copied into K[s]
    # (a view K[s] would cost a reference count per call)
    for s in range(1, 13):
        for i in range(N):
            ytmp[i] = 0.0
        for q in range(_STAGE_L[s]):  # the nonzero a_sj (b_j), in increasing j
            j = _STAGE_J[s, q]
            c = _STAGE_C[s, q]
            for i in range(N):
                ytmp[i] += K[j, i] * c
        for i in range(N):
            ytmp[i] = y[i] + h * ytmp[i]
        rhs_kernel(ytmp, u, P, ynew, vel, force)
        for i in range(N):
            K[s, i] = ynew[i]
    for i in range(N):
        ynew[i] = ytmp[i]


@njit
def _dop853_error(y, ynew, K, h, rtol, atol):
    e5 = 0.0
    e3 = 0.0
    for i in range(N):
        sc = atol + max(abs(y[i]), abs(ynew[i])) * rtol
        a5 = 0.0
        a3 = 0.0
        for q in range(_ERROR_J.shape[0]):
            kj = K[_ERROR_J[q], i]
            a5 += kj * _ERROR_E5[q]
            a3 += kj * _ERROR_E3[q]
        a5 /= sc
        a3 /= sc
        e5 += a5 * a5
        e3 += a3 * a3
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * N)


@njit
def dop853_advance(
    y, f, t, t_bound, h_abs, rejected, u, P, rtol, atol, gap_sign, check_gap, K, ynew, ytmp, vel, force, counters
):
    """Advance ``y`` (and its derivative ``f``) in place from t to exactly t_bound.

    counters: [nfev, accepted, rejected(, budget of nfev)]; past the budget (checked before every attempt) or
    :data:`DOP853_MAX_STEPS` steps the status is ``MAX_STEPS`` (kind ``"budget"``). ``rejected``: whether the attempt
    at t follows a rejected one (False, except when continuing a run that stopped there: :func:`dop853_solve_into`).
    Returns (status, t reached, next |h|, whether the next attempt follows a rejected one).
    """
    while t < t_bound:
        min_step = 10.0 * abs(next_up(t) - t)
        if not rejected and h_abs < min_step:  # a new step starts at t
            h_abs = min_step
        while True:
            if h_abs < min_step:
                return STEP_COLLAPSE, t, h_abs, rejected
            if counters[1] + counters[2] > DOP853_MAX_STEPS or (counters.size > 3 and counters[0] > counters[3]):
                return MAX_STEPS, t, h_abs, rejected
            t_new = t + h_abs
            if t_new > t_bound:
                t_new = t_bound
            h = t_new - t
            h_abs = abs(h)
            _dop853_stages(y, f, h, u, P, K, ynew, ytmp, vel, force)
            counters[0] += 12
            err = _dop853_error(y, ynew, K, h, rtol, atol)
            if err < 1.0:
                if err == 0.0:
                    factor = _MAX_FACTOR
                else:
                    factor = min(_MAX_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
                if rejected:
                    factor = min(1.0, factor)
                h_abs *= factor
                break
            factor = _SAFETY * err**_ERROR_EXPONENT
            if not factor > _MIN_FACTOR:  # also for err = nan, like scipy's max(0.2, nan)
                factor = _MIN_FACTOR
            h_abs *= factor
            rejected = True
            counters[2] += 1
        rejected = False
        counters[1] += 1
        t = t_new
        for i in range(N):
            y[i] = ynew[i]
            f[i] = K[12, i]
        st = _state_status(y, gap_sign, check_gap)
        if st != OK:
            return st, t, h_abs, False
    return OK, t, h_abs, False


@njit
def dop853_solve_into(
    y0, times, u, P, rtol, atol, energy_tol, Y, counters, fail, y, f, K, ynew, ytmp, vel, force, carry
):
    """:func:`dop853_solve` with work arrays ``y``, ``f``, ``ynew``, ``ytmp`` (11,), ``K`` (13, 11), ``vel``
    (7,), ``force`` (4,) passed in (allocates nothing: the CUDA target compiles it as a device
    function); ``counters`` (3,) or (4,) [nfev, accepted, rejected(, budget of nfev)]; ``fail`` (2,) or
    (3,): [t of failure, last |H − H₀|(, failing row)].

    ``carry`` (:func:`carry_size`,) float64 is where the run stands (:data:`CARRY_T` …): all zeros, it starts at
    ``times[0]`` from ``y0``; a run stopped by its budget of evaluations (``MAX_STEPS``) leaves there its state, time,
    step size, output row and counts, and a call with a larger ``counters[3]`` continues from them (``y0`` unread,
    ``counters[:3]`` restored): the result is bit for bit that of one call with the larger budget. Any other outcome
    marks the run finished (``carry[CARRY_K] = -1``)."""
    check_energy = energy_tol < np.inf and no_control(u)
    k0 = int(carry[CARRY_K])
    if k0 == 0:  # a fresh start at times[0]
        for i in range(N):
            y[i] = y0[i]
        rhs_kernel(y, u, P, f, vel, force)
        counters[0] += 1
        gap_sign = 1.0 if y[7] > y[8] else -1.0
        check_gap = not may_cross(y, u, P)
        H0 = energy_kernel(y, P, vel, force)
        for i in range(N):
            Y[i, 0] = y[i]
        t = times[0]
        fail[0] = t
        h_abs = dop853_initial_step_into(
            y, f, t, times[times.size - 1], u, P, rtol, atol, vel, force, ytmp, ynew, counters
        )
        rejected = False
        k0 = 1
    else:  # go on from where the budget stopped the run
        for i in range(N):
            y[i] = carry[CARRY_Y + i]
            f[i] = carry[CARRY_Y + N + i]
        for i in range(3):
            counters[i] = int(carry[CARRY_COUNTERS + i])
        t = carry[CARRY_T]
        h_abs = carry[CARRY_H]
        rejected = carry[CARRY_REJECTED] != 0.0
        gap_sign = carry[CARRY_GAP_SIGN]
        check_gap = carry[CARRY_CHECK_GAP] != 0.0
        H0 = carry[CARRY_H0]
    carry[CARRY_K] = -1.0
    for k in range(k0, times.size):
        if fail.size > 2:
            fail[2] = k
        st, t, h_abs, rejected = dop853_advance(
            y, f, t, times[k], h_abs, rejected, u, P, rtol, atol, gap_sign, check_gap, K, ynew, ytmp, vel, force,
            counters,
        )  # fmt: skip
        fail[0] = t
        for i in range(N):
            Y[i, k] = y[i]
        if st == MAX_STEPS:  # where to go on from
            carry[CARRY_T] = t
            carry[CARRY_H] = h_abs
            carry[CARRY_K] = k
            carry[CARRY_REJECTED] = 1.0 if rejected else 0.0
            carry[CARRY_GAP_SIGN] = gap_sign
            carry[CARRY_CHECK_GAP] = 1.0 if check_gap else 0.0
            carry[CARRY_H0] = H0
            for i in range(3):
                carry[CARRY_COUNTERS + i] = counters[i]
            for i in range(N):
                carry[CARRY_Y + i] = y[i]
                carry[CARRY_Y + N + i] = f[i]
        if st != OK:
            return st
        if check_energy:
            dH = abs(energy_kernel(y, P, vel, force) - H0)
            fail[1] = dH
            if dH > energy_tol:
                return ENERGY
    return OK


@njit
def dop853_solve(y0, times, u, P, rtol, atol, energy_tol, Y, counters, fail, carry=None):
    """DOP853 from ``times[0]`` through every output time; Y (11, len(times)) receives the states.

    counters (3,) or (4,) int64: [nfev, accepted, rejected(, budget of nfev)]; fail (2,): [t of failure, |H − H₀| at the
    last check]; ``carry`` (optional): where the run stands, to continue a run its budget stopped
    (:func:`dop853_solve_into`). Returns the status. (:func:`dop853_solve_into` with its work arrays allocated.)
    """
    if carry is None:
        where = np.zeros(CARRY_Y + 2 * N)
    else:
        where = carry
    return dop853_solve_into(
        y0,
        times,
        u,
        P,
        rtol,
        atol,
        energy_tol,
        Y,
        counters,
        fail,
        np.empty(N),
        np.empty(N),
        np.empty((13, N)),
        np.empty(N),
        np.empty(N),
        np.empty(7),
        np.empty(4),
        where,
    )


@njit
def _dop853_env(y, u, P, dt, h, rtol, atol, energy_tol, out, K, ynew, ytmp, vel, force, f, counters):
    for i in range(N):
        out[i] = y[i]
    rhs_kernel(out, u, P, f, vel, force)
    counters[0] += 1
    if h <= 0.0:
        h = dop853_initial_step(out, f, 0.0, dt, u, P, rtol, atol, vel, force, ytmp, counters)
    gap_sign = 1.0 if y[7] > y[8] else -1.0
    st, t, h, _ = dop853_advance(
        out, f, 0.0, dt, h, False, u, P, rtol, atol, gap_sign, not may_cross(y, u, P), K, ynew, ytmp, vel, force,
        counters,
    )  # fmt: skip
    if st != OK:
        return st
    if energy_tol < np.inf and no_control(u):
        if abs(energy_kernel(out, P, vel, force) - energy_kernel(y, P, vel, force)) > energy_tol:
            return ENERGY
    return OK


# --------------------------------------------------------------------------------------------- RK4
@njit
def _rk4_step(y, h, u, P, k1, k2, k3, k4, ytmp, vel, force):
    """One classical RK4 step in place; returns the chart turn h·max(|ω3|, |θ̇|) at the start."""
    rhs_kernel(y, u, P, k1, vel, force)
    turn = h * max(abs(vel[2]), abs(vel[3]))
    for i in range(N):
        ytmp[i] = y[i] + 0.5 * h * k1[i]
    rhs_kernel(ytmp, u, P, k2, vel, force)
    for i in range(N):
        ytmp[i] = y[i] + 0.5 * h * k2[i]
    rhs_kernel(ytmp, u, P, k3, vel, force)
    for i in range(N):
        ytmp[i] = y[i] + h * k3[i]
    rhs_kernel(ytmp, u, P, k4, vel, force)
    for i in range(N):
        y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    return turn


@njit
def _n_steps(span, hmax):
    n = int(math.ceil(span / hmax - 1e-9))
    return max(n, 1)


@njit
def _rk4_advance(y, span, hmax, u, P, gap_sign, check_gap, work, vel, force, counters):
    n = _n_steps(span, hmax)
    h = span / n
    for j in range(n):
        turn = _rk4_step(y, h, u, P, work[0], work[1], work[2], work[3], work[4], vel, force)
        counters[0] += 4
        counters[1] += 1
        if turn > MAX_TURN:
            return UNDER_RESOLVED, j * h
        st = _state_status(y, gap_sign, check_gap)
        if st != OK:
            return st, (j + 1) * h
    return OK, span


# --------------------------------------------------------------------------------------------- splitting
@njit
def _masked_rates(y, tmp, keep, P, vel, force):
    """kinetic_kernel on y with every momentum except those flagged in ``keep`` set to zero."""
    for i in range(7):
        tmp[i] = y[i] if keep[i] else 0.0
    for i in range(7, N):
        tmp[i] = y[i]
    kinetic_kernel(tmp, P, vel, force)


_KEEP_T = np.array([False, False, False, False, True, True, True])
_KEEP_H1 = np.array([True, False, False, False, False, False, False])
_KEEP_H2 = np.array([False, True, False, False, False, False, False])
_KEEP_H3 = np.array([False, False, True, True, False, False, False])


@njit
def _drift(y, h, P, tmp, vel, force):
    _masked_rates(y, tmp, _KEEP_T, P, vel, force)
    y[7] += h * vel[4]
    y[8] += h * vel[5]
    y[9] += h * vel[6]


@njit
def _kick(y, h, u, P):
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    y[4] -= h * gl
    y[5] -= h * gm
    y[6] += h * (u[3] - gr)


@njit
def _torque(y, h, u):
    y[0] += h * u[0]
    y[1] += h * u[1]
    y[2] += h * u[2]


@njit
def _flow_h1(y, h, P, tmp, vel, force):
    _masked_rates(y, tmp, _KEEP_H1, P, vel, force)
    a = P[8] * vel[0] * h
    c = math.cos(a)
    s = math.sin(a)
    s2 = y[1]
    s3 = y[2]
    y[1] = c * s2 - s * s3
    y[2] = s * s2 + c * s3
    y[5] += h * force[2]
    y[6] += h * force[3]


@njit
def _flow_h2(y, h, P, tmp, vel, force):
    _masked_rates(y, tmp, _KEEP_H2, P, vel, force)
    b = P[8] * vel[1] * h
    c = math.cos(b)
    s = math.sin(b)
    s1 = y[0]
    s3 = y[2]
    y[0] = c * s1 + s * s3
    y[2] = -s * s1 + c * s3
    y[4] += h * force[1]
    y[6] += h * force[3]


@njit
def _flow_h3(y, h, P, tmp, vel, force):
    _masked_rates(y, tmp, _KEEP_H3, P, vel, force)
    a = P[8] * vel[2] * h
    c = math.cos(a)
    s = math.sin(a)
    s1 = y[0]
    s2 = y[1]
    y[0] = c * s1 - s * s2
    y[1] = s * s1 + c * s2
    y[10] += h * vel[3]
    y[4] += h * force[1]
    y[5] += h * force[2]
    return abs(h) * max(abs(vel[2]), abs(vel[3]))


@njit
def strang_step(y, h, u, P, tmp, vel, force):
    """One symmetric Strang step (module docstring) in place; returns the chart turn of H3."""
    _drift(y, 0.5 * h, P, tmp, vel, force)
    _torque(y, 0.5 * h, u)
    _kick(y, h, u, P)
    _flow_h1(y, 0.5 * h, P, tmp, vel, force)
    _flow_h2(y, 0.5 * h, P, tmp, vel, force)
    turn = _flow_h3(y, h, P, tmp, vel, force)
    _flow_h2(y, 0.5 * h, P, tmp, vel, force)
    _flow_h1(y, 0.5 * h, P, tmp, vel, force)
    _torque(y, 0.5 * h, u)
    _drift(y, 0.5 * h, P, tmp, vel, force)
    return turn


@njit
def _split_advance(y, span, hmax, coeffs, u, P, gap_sign, check_gap, tmp, vel, force, counters):
    n = _n_steps(span, hmax)
    h = span / n
    for j in range(n):
        turn = 0.0
        for c in coeffs:
            turn = max(turn, strang_step(y, c * h, u, P, tmp, vel, force))
        counters[0] += coeffs.size
        counters[1] += 1
        if turn > MAX_TURN:
            return UNDER_RESOLVED, j * h
        st = _state_status(y, gap_sign, check_gap)
        if st != OK:
            return st, (j + 1) * h
    return OK, span


# --------------------------------------------------------------------------------------------- fixed-step drivers
@njit
def _fixed_advance(kind, y, span, hmax, coeffs, u, P, gap_sign, check_gap, work, vel, force, counters):
    if kind == 0:
        return _rk4_advance(y, span, hmax, u, P, gap_sign, check_gap, work, vel, force, counters)
    return _split_advance(y, span, hmax, coeffs, u, P, gap_sign, check_gap, work[0], vel, force, counters)


@njit
def fixed_solve_into(kind, coeffs, y0, times, u, P, h, energy_tol, Y, counters, fail, y, work, vel, force):
    """:func:`fixed_solve` with work arrays ``y`` (11,), ``work`` (≥5, 11), ``vel`` (7,), ``force`` (4,)
    passed in (allocates nothing: the CUDA target compiles it as a device function); ``fail`` (2,) or
    (3,): [t of failure, last |H − H₀|(, failing row)]."""
    for i in range(N):
        y[i] = y0[i]
    gap_sign = 1.0 if y[7] > y[8] else -1.0
    check_gap = not may_cross(y, u, P)
    check_energy = energy_tol < np.inf and no_control(u)
    H0 = energy_kernel(y, P, vel, force)
    for i in range(N):
        Y[i, 0] = y[i]
    fail[0] = times[0]
    for k in range(1, times.size):
        if fail.size > 2:
            fail[2] = k
        st, dt_done = _fixed_advance(
            kind, y, times[k] - times[k - 1], h, coeffs, u, P, gap_sign, check_gap, work, vel, force, counters
        )
        fail[0] = times[k - 1] + dt_done
        for i in range(N):
            Y[i, k] = y[i]
        if st != OK:
            return st
        if check_energy:
            dH = abs(energy_kernel(y, P, vel, force) - H0)
            fail[1] = dH
            if dH > energy_tol:
                return ENERGY
    return OK


@njit
def fixed_solve(kind, coeffs, y0, times, u, P, h, energy_tol, Y, counters, fail):
    """Fixed-step integration through every output time (kind 0: RK4, 1: splitting with ``coeffs``).

    Y (11, len(times)) receives the states; counters (3,) int64 [nfev, steps, 0]; fail (2,)
    [t of failure, last |H − H₀|]. Returns the status. (:func:`fixed_solve_into` with its work arrays allocated.)
    """
    return fixed_solve_into(
        kind,
        coeffs,
        y0,
        times,
        u,
        P,
        h,
        energy_tol,
        Y,
        counters,
        fail,
        np.empty(N),
        np.empty((5, N)),
        np.empty(7),
        np.empty(4),
    )


@njit
def _fixed_env(kind, coeffs, y, u, P, dt, h, energy_tol, out, work, vel, force, counters):
    for i in range(N):
        out[i] = y[i]
    gap_sign = 1.0 if y[7] > y[8] else -1.0
    st, dt_done = _fixed_advance(
        kind, out, dt, h, coeffs, u, P, gap_sign, not may_cross(y, u, P), work, vel, force, counters
    )
    if st != OK:
        return st
    if energy_tol < np.inf and no_control(u):
        if abs(energy_kernel(out, P, vel, force) - energy_kernel(y, P, vel, force)) > energy_tol:
            return ENERGY
    return OK


# --------------------------------------------------------------------------------------------- the env step
@njit
def env_step_into(kind, coeffs, y, u, P, dt, h, rtol, atol, energy_tol, out, K, ynew, ytmp, vel, force, f, counters):
    """One environment step of method ``kind`` (:data:`~.specs.KIND_CODES`; ``coeffs`` for a splitting)
    from t = 0 to exactly dt, with its work arrays ``K`` (13, N), ``ynew``, ``ytmp``, ``f`` (N,), ``vel``
    (7,), ``force`` (4,) passed in (allocates nothing); ``counters`` (3,) accumulates [nfev, steps, rejected]."""
    if kind == DOP853_KIND:
        return _dop853_env(y, u, P, dt, h, rtol, atol, energy_tol, out, K, ynew, ytmp, vel, force, f, counters)
    return _fixed_env(kind, coeffs, y, u, P, dt, h, energy_tol, out, K, vel, force, counters)


@njit
def env_step(kind, coeffs, y, u, P, dt, h, rtol, atol, energy_tol, out, counters):
    """One environment step (module docstring): :func:`env_step_into` with its work arrays allocated."""
    return env_step_into(
        kind,
        coeffs,
        y,
        u,
        P,
        dt,
        h,
        rtol,
        atol,
        energy_tol,
        out,
        np.empty((13, N)),
        np.empty(N),
        np.empty(N),
        np.empty(7),
        np.empty(4),
        np.empty(N),
        counters,
    )


@njit
def energy_series(Y, P, out):
    """H (eq. (41) of [1]) of every column of the packed states ``Y`` (11, m) into ``out`` (m,)."""
    vel = np.empty(7)
    force = np.empty(4)
    y = np.empty(11)
    for k in range(Y.shape[1]):
        for i in range(11):
            y[i] = Y[i, k]
        out[k] = energy_kernel(y, P, vel, force)


@njit
def rhs_compiled(y, u, P, out):
    """dy/dt by the jitted physics kernel (for tests: equals :func:`flatbody_env.physics.equations.rhs`)."""
    rhs_kernel(y, u, P, out, np.empty(7), np.empty(4))
