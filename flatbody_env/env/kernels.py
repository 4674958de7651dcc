"""The environment's per-step bookkeeping as plain-float kernels (compiled on the fast path).

After the integrator has advanced a body, :func:`post_step` decides whether the new state is in
the documented domain, keeps the old state otherwise, and fills the observation, the named
reward terms of :class:`~flatbody_env.env.task.ReachStationaryEllipse` and the scalars of ``info``
— one pass of float arithmetic, no numpy calls, so the same code runs in Python and, through
:func:`flatbody_env.integrators.jit.jit_copy`, compiled (single body, and :func:`post_step_batch`
over N bodies in one call).

Configuration vector ``cfg`` (float64, :data:`CFG_SIZE`)

=====  ==================  =================================================
index  name                meaning
=====  ==================  =================================================
0–5    weights             w_shape, w_spin, w_tumble, w_rest, w_action, failure_penalty
6      success_tolerance   distance at or below which ``is_success``
7–8    stretch_bounds      domain of λ and μ
9–10   rho_bounds          domain of ϱ
11     momentum_bound      domain of s and p (absolute value)
12     gap_min             smallest |λ − μ|/(λ + μ) (two-polar integrators only)
13     check_gap           1 for a two-polar integrator, else 0
=====  ==================  =================================================

Scalars ``sc`` (float64, 4): distance, energy H (eq. (41) of the paper), |s|², domain code.
Domain codes (:data:`DOMAIN_CODES`): 0 inside, 1 non-finite, 2 λ, 3 μ, 4 ϱ, 5 momentum, 6 gap.
"""

from __future__ import annotations

import math

from flatbody_env.physics.hamiltonian import kinetic_kernel
from flatbody_env.physics.potentials import potential_kernel

CFG_SIZE = 14
DOMAIN_CODES = ("inside", "non-finite state", "lambda", "mu", "rho", "momentum", "gap")


def domain_code(y, cfg):
    """0 if ``y`` lies in the documented domain, else the code of the first violation."""
    for i in range(11):
        if not math.isfinite(y[i]):
            return 1
    if y[7] < cfg[7] or y[7] > cfg[8]:
        return 2
    if y[8] < cfg[7] or y[8] > cfg[8]:
        return 3
    if y[9] < cfg[9] or y[9] > cfg[10]:
        return 4
    for i in range(7):
        if abs(y[i]) > cfg[11]:
            return 5
    if cfg[13] != 0.0 and abs(y[7] - y[8]) < cfg[12] * (y[7] + y[8]):
        return 6
    return 0


def post_step(y_old, y_new, status, a, n_act, tgt, cfg, P, y_out, obs, terms, sc, vel, force):
    """Accept or reject the step, then observe and score (module docstring).

    Parameters
    ----------
    y_old, y_new : (11,)
        State before the step and the integrator's result.
    status : int
        The integrator's status (0 = success).
    a : (n,)
        The clipped action (zeros for ``control="none"``); ``n_act`` entries are used.
    tgt : (4,)
        Target (λ*, μ*, ϱ*, s3*).
    cfg : (14,), P : (9,)
        Task/domain configuration and kernel parameters.
    y_out : (11,), output
        The state kept (y_new if accepted, else y_old).
    obs : (16,), output (float32 or float64)
    terms : (6,), output
        shape, spin, tumble, rest, action, failure.
    sc : (4,), output
        distance, energy, |s|², domain code.
    vel, force : (7,), (4,)
        Work space.

    Returns
    -------
    int
        1 if the episode terminates (integrator failure or left domain), else 0.
    """
    code = 0
    if status == 0:
        code = domain_code(y_new, cfg)
    ended = 1 if (status != 0 or code != 0) else 0
    for i in range(11):
        y_out[i] = y_old[i] if ended else y_new[i]
    y = y_out
    J = P[0]
    J3 = P[2]
    j3r2 = J3 * y[9] * y[9]
    w1 = y[0] / (J * y[8] * y[8] + j3r2)  # ω1 = s1 / (Jμ² + J3ϱ²) (after eq. (31) of the paper)
    w2 = y[1] / (J * y[7] * y[7] + j3r2)  # ω2 = s2 / (Jλ² + J3ϱ²)
    dl = y[7] - tgt[0]
    dm = y[8] - tgt[1]
    dr = y[9] - tgt[2]
    ds = y[2] - tgt[3]
    shape = math.sqrt(dl * dl + dm * dm + dr * dr)
    tumble = math.sqrt(w1 * w1 + w2 * w2)
    rest = math.sqrt(y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
    act = 0.0
    for i in range(n_act):
        act += a[i] * a[i]
    terms[0] = -cfg[0] * shape
    terms[1] = -cfg[1] * abs(ds)
    terms[2] = -cfg[2] * tumble
    terms[3] = -cfg[3] * rest
    terms[4] = -cfg[4] * act
    terms[5] = -cfg[5] if ended else 0.0
    sc[0] = math.sqrt(shape * shape + ds * ds + tumble * tumble + rest * rest)
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    sc[1] = kinetic_kernel(y, P, vel, force) + v
    sc[2] = y[0] * y[0] + y[1] * y[1] + y[2] * y[2]
    sc[3] = float(code)
    for i in range(10):
        obs[i] = y[i]
    obs[10] = math.sin(y[10])
    obs[11] = math.cos(y[10])
    for i in range(4):
        obs[12 + i] = tgt[i]
    return ended


def post_step_batch(Y_old, Y_new, status, A, n_act, T, cfg, P, Y_out, OBS, TERMS, SC, ENDED, vel, force):
    """:func:`post_step` for N bodies in structure-of-arrays layout.

    ``Y_old``, ``Y_new``, ``Y_out``: (11, N); ``status``: (N,); ``A``: (N, n); ``T``: (N, 4);
    ``OBS``: (N, 16); ``TERMS``: (6, N); ``SC``: (4, N); ``ENDED``: (N,) output.
    """
    for k in range(Y_old.shape[1]):
        ENDED[k] = post_step(Y_old[:, k], Y_new[:, k], status[k], A[k], n_act, T[k], cfg, P, Y_out[:, k], OBS[k], TERMS[:, k], SC[:, k], vel, force)


def controls_kernel(action, mask, limits, a_out, u_out):
    """Clip the action to [−1, 1] into ``a_out`` and scale the driven controls into ``u_out`` (4,).

    ``mask`` (4,) marks which of (τ1, τ2, τ3, f_ϱ) the action drives, in order; ``limits`` (4,)
    holds torque_limit ×3 and force_limit. Returns False if the action is not finite.
    """
    for i in range(action.size):
        if not math.isfinite(action[i]):
            return False
        a_out[i] = min(1.0, max(-1.0, action[i]))
    k = 0
    for j in range(4):
        if mask[j]:
            u_out[j] = a_out[k] * limits[j]
            k += 1
        else:
            u_out[j] = 0.0
    return True
