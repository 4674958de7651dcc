"""The environment's per-step bookkeeping as plain-float kernels (compiled by :mod:`.compiled`).

After the integrator has advanced a body, :func:`post_step` decides whether the new state is in
the documented domain, keeps the old state otherwise, and fills the observation, the named
reward terms and the scalars of ``info`` — by calling the task's kernels
(:func:`~flatbody_env.env.task.domain_code`, :func:`~flatbody_env.env.task.score_kernel`,
:func:`~flatbody_env.env.task.observe_kernel`, where each formula lives) and the energy H of
eq. (41) of the paper. No numpy allocation, so the same code runs in Python (generic integrators)
and, through :func:`flatbody_env.integrators.jit.retarget`, compiled (single body; and
:func:`post_step_lanes`, the same decisions and formulas over N bodies in loops numba vectorises).

``cfg`` is the task's configuration vector (:meth:`~flatbody_env.env.task.ReachStationaryEllipse.kernel_config`);
``P`` the body's kernel parameters (:meth:`~flatbody_env.physics.body.Body.kernel_params`).
Scalars ``sc`` (float64, 4): distance, energy H, |s|² (the Casimir), domain code.
"""

from __future__ import annotations


from flatbody_env.env.task import CFG_SIZE, DOMAIN_CODES, domain_code, observe_kernel, score_kernel
from flatbody_env.physics.hamiltonian import kinetic_iso, kinetic_kernel
from flatbody_env.physics.potentials import potential_kernel


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
    act = 0.0
    for i in range(n_act):
        act += a[i] * a[i]
    sc[0] = score_kernel(y, tgt, act, ended, cfg, P, terms)
    v, gl, gm, gr = potential_kernel(P[3], P[4], P[5], P[6], P[7], y[7], y[8], y[9])
    if P[0] == P[1]:  # the energy alone (the compiled code drops the gradients kinetic_iso also returns)
        sc[1] = kinetic_iso(y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7], y[8], y[9], P[0], P[2])[0] + v
    else:
        sc[1] = kinetic_kernel(y, P, vel, force) + v
    sc[2] = y[0] * y[0] + y[1] * y[1] + y[2] * y[2]
    sc[3] = float(code)
    observe_kernel(y, tgt, obs)
    return ended


def post_step_lanes(Y_old, Y_new, status, A, n_act, T, cfg, P, Y_out, OBS, TERMS, SC, ENDED, ACT2, Tt, vel, force, yk):
    """:func:`post_step` for N bodies, bit for bit, in loops over the bodies that numba vectorises.

    The decision (domain, kept state) runs lane by lane as :func:`post_step` does; then the energy
    (:func:`~flatbody_env.physics.hamiltonian.kinetic_iso` and the potential on scalars for J1 = J2,
    :func:`~flatbody_env.physics.hamiltonian.kinetic_kernel` per body otherwise) and the Casimir in one
    loop over lanes, the reward terms and the distance by the task's
    :func:`~flatbody_env.env.task.score_kernel` on the whole (11, N) array (it is written for both),
    and the observation by :func:`~flatbody_env.env.task.observe_kernel` per body.

    ``Y_old``, ``Y_new``, ``Y_out``: (11, N); ``status``: (N,); ``A``: (N, n) (``n_act`` columns used);
    ``T``: (N, 4); ``P``: (9, N) each body's kernel parameters (one body or one drawn per episode in each lane);
    ``OBS``: (N, 16); ``TERMS``: (6, N); ``SC``: (4, N); ``ENDED``: (N,) output; work:
    ``ACT2`` (N,), ``Tt`` (4, N), ``vel`` (7,), ``force`` (4,), ``yk`` (11,).
    """
    n = Y_old.shape[1]
    for k in range(n):
        code = 0
        if status[k] == 0:
            for i in range(11):  # a contiguous copy: the domain check runs faster on it than on a column view
                yk[i] = Y_new[i, k]
            code = domain_code(yk, cfg)
        ended = 1 if (status[k] != 0 or code != 0) else 0
        ENDED[k] = ended
        SC[3, k] = float(code)
        act = 0.0
        for i in range(n_act):
            act += A[k, i] * A[k, i]
        ACT2[k] = act
        for i in range(4):
            Tt[i, k] = T[k, i]
    for i in range(11):
        for k in range(n):
            Y_out[i, k] = Y_old[i, k] if ENDED[k] else Y_new[i, k]
    SC[0] = score_kernel(Y_out, Tt, ACT2, ENDED, cfg, P, TERMS)
    kind = P[3, 0]
    alike = True  # J1 = J2 and one potential kind in every lane: one loop numba vectorises
    for k in range(n):
        if P[0, k] != P[1, k] or P[3, k] != kind:
            alike = False
    if alike:
        for k in range(n):
            v, gl, gm, gr = potential_kernel(
                kind, P[4, k], P[5, k], P[6, k], P[7, k], Y_out[7, k], Y_out[8, k], Y_out[9, k]
            )
            kin = kinetic_iso(
                Y_out[0, k],
                Y_out[1, k],
                Y_out[2, k],
                Y_out[3, k],
                Y_out[4, k],
                Y_out[5, k],
                Y_out[6, k],
                Y_out[7, k],
                Y_out[8, k],
                Y_out[9, k],
                P[0, k],
                P[2, k],
            )
            SC[1, k] = kin[0] + v
    else:  # each lane as post_step computes it
        for k in range(n):
            for i in range(11):
                yk[i] = Y_out[i, k]
            v, gl, gm, gr = potential_kernel(P[3, k], P[4, k], P[5, k], P[6, k], P[7, k], yk[7], yk[8], yk[9])
            if P[0, k] == P[1, k]:
                kin = kinetic_iso(
                    yk[0], yk[1], yk[2], yk[3], yk[4], yk[5], yk[6], yk[7], yk[8], yk[9], P[0, k], P[2, k]
                )
                SC[1, k] = kin[0] + v
            else:
                SC[1, k] = kinetic_kernel(yk, P[:, k], vel, force) + v
    for k in range(n):
        SC[2, k] = Y_out[0, k] * Y_out[0, k] + Y_out[1, k] * Y_out[1, k] + Y_out[2, k] * Y_out[2, k]
        observe_kernel(Y_out[:, k], T[k], OBS[k])


__all__ = ["CFG_SIZE", "DOMAIN_CODES", "domain_code", "post_step", "post_step_lanes"]
