"""The whole env step and the resets as per-body kernels: one source for the CPU (numba) and a CUDA GPU.

A body's environment step — the controls from its action, the dynamics, the domain check, the
observation, the reward terms, the termination, the truncation and the autoreset — is the plain-Python
function :func:`step_body`, and a body's reset (a target and a start drawn from a counter-based
generator, then observed) is :func:`reset_body`. They call the env's own kernels and change none of
them: :func:`~flatbody_env.env.kernels.controls_batch` (on the body's row),
:func:`~flatbody_env.integrators.twopolar_kernels.env_step_into` (the integrator),
:func:`~flatbody_env.env.kernels.post_step` (domain, observation, reward terms, energy),
:func:`~flatbody_env.env.sampling.candidate_kernel` (target shape, the settling-rate table's rule,
stability), :func:`~flatbody_env.env.sampling.initial_state_kernel` and
:func:`~flatbody_env.env.sampling.ball_state_kernel` (the start). numba compiles them for the CPU
(:func:`~flatbody_env.integrators.jit.retarget`: :func:`step_lanes`, :func:`reset_lanes`, a loop over the
bodies) and, from the same source, for CUDA (:func:`flatbody_env.integrators.cuda.env_step` with
``task=``: one thread per body, **one kernel launch per env step**). :class:`DeviceBatch` holds a batch's
arrays on either.

Random numbers: Philox-4x32-10 (Salmon et al., SC'11, the generator of cuRAND and JAX), written as plain
integer arithmetic on uint64 holding 32-bit words (a 32 × 32-bit product fits, so nothing overflows on
either target or in Python). Uniform number j of body b's episode e is a pure function of
(key, b, e, j) (:func:`uniform_at`): the key comes from ``reset(seed=)`` (numpy's ``SeedSequence``), each
body counts its own episodes. No state is carried between draws, so every thread draws on its own and
the CPU and the GPU draw the same numbers. Uniform j plays the part of the j-th number of the CPU
sampler's block (:func:`~flatbody_env.env.sampling.sample_episode_kernel`): three per candidate shape,
then the start's. What differs from ``FlatBody-v0``'s numpy stream: the numbers (another generator, so
other episodes for a seed; the same distributions, tested over 10⁴ draws), and the rare shape the table
is unsure about (2 in 40,000 draws for the shipped table) is rejected here where the CPU runs the exact
Riccati test — the GPU has none.

Arrays of a batch of N bodies (structure of arrays; the layout of :class:`DeviceBatch`):

* ``Y`` (11, N) states; ``T`` (4, N) targets (λ*, μ*, ϱ*, s3*);
* ``OBS``, ``FINAL`` (N, 16) float32 observations and final observations (rows of bodies that ended);
* ``INFO`` (12, N) float64: 0 reward, 1–6 the reward terms (:data:`~flatbody_env.env.task.REWARD_TERMS`),
  7 distance, 8 energy H, 9 |s|², 10 domain code, 11 t (the episode time of the step);
* ``I`` (4, N) int64: 0 episode clock (steps), 1 episodes drawn, 2 integrator status, 3 nfev;
* ``ENDS`` (3, N) uint8: terminated, truncated, autoreset pending (NEXT_STEP mode);
* ``FLAGS`` (2,) int64: an error code (:data:`ERR_ACTION`, :data:`ERR_NO_TARGET`, :data:`ERR_START`) and
  a body that raised it (0: none).
"""

from __future__ import annotations

import numpy as np
from numba import float64, int64

from flatbody_env.env.kernels import controls_batch, post_step
from flatbody_env.env.sampling import (
    BALL_DRAWS,
    MAX_ATTEMPTS,
    NO_TARGET,
    START_BALL,
    START_NONE,
    ball_state_kernel,
    candidate_kernel,
    initial_state_kernel,
)
from flatbody_env.env.targets import REJECT, UNSURE
from flatbody_env.integrators.twopolar_kernels import env_step_into
from flatbody_env.physics.validation import ENV_STEP_MAX_NFEV

STREAM_EPISODE, STREAM_CLOCK = 0, 1
"""Philox streams (counter word 3): a reset's draws, the staggered clock."""
ERR_ACTION, ERR_NO_TARGET, ERR_START = 1, 2, 3
"""Codes of ``FLAGS[0]``: a non-finite action (that body was not stepped), no target in :data:`~.sampling.MAX_ATTEMPTS`
candidates, a start outside the domain."""
INFO_ROWS = 12
I_ROWS = 4
ENDS_ROWS = 3


# --------------------------------------------------------------------------------------------- generator
def philox4x32(k0, k1, c0, c1, c2, c3):
    """Philox-4x32-10 of the counter (c0, c1, c2, c3) under the key (k0, k1), 32-bit words held in uint64:
    the four output words."""
    m = np.uint64(0xFFFFFFFF)
    s = np.uint64(32)
    x0 = np.uint64(c0) & m
    x1 = np.uint64(c1) & m
    x2 = np.uint64(c2) & m
    x3 = np.uint64(c3) & m
    key0 = np.uint64(k0) & m
    key1 = np.uint64(k1) & m
    for _ in range(10):
        p0 = np.uint64(0xD2511F53) * x0
        p1 = np.uint64(0xCD9E8D57) * x2
        y0 = (p1 >> s) ^ x1 ^ key0
        y1 = p1 & m
        y2 = (p0 >> s) ^ x3 ^ key1
        y3 = p0 & m
        x0 = y0
        x1 = y1
        x2 = y2
        x3 = y3
        key0 = (key0 + np.uint64(0x9E3779B9)) & m
        key1 = (key1 + np.uint64(0xBB67AE85)) & m
    return x0, x1, x2, x3


def uniform_at(k0, k1, body, episode, stream, j):
    """Uniform number ``j`` in [0, 1) (53 random bits, numpy's construction from two words) of ``body``'s
    ``episode`` in ``stream``: words of Philox at counter (j // 2, episode, body, stream)."""
    x0, x1, x2, x3 = philox4x32(k0, k1, j >> 1, episode, body, stream)
    if j & 1:
        x0 = x2
        x1 = x3
    a = x0 >> np.uint64(5)
    b = x1 >> np.uint64(6)
    return (float(a) * 67108864.0 + float(b)) * (1.0 / 9007199254740992.0)


# --------------------------------------------------------------------------------------------- reset
def draw_episode(
    k0,
    k1,
    body,
    episode,
    scfg,
    P,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    y,
    tg,
    pot,
    table_code,
    cand,
    uu,
):
    """One episode of ``body`` from its uniforms (:func:`uniform_at`, stream :data:`STREAM_EPISODE`): the loop of
    :func:`~flatbody_env.env.sampling.sample_episode_kernel` with the exact test's answer "reject" for the shapes
    the table is unsure about. ``y`` (11,) the start, ``tg`` (6,) (λ*, μ*, ϱ*, s3*, p_θ*, sign); ``uu`` (12,)
    work. Returns the uniforms used, or :data:`~flatbody_env.env.sampling.NO_TARGET`."""
    ball = scfg[13] == START_BALL
    m = BALL_DRAWS if ball else (0 if scfg[13] == START_NONE else (10 if scfg[7] != 0.0 else 9))
    for a in range(MAX_ATTEMPTS):
        j = 3 * a
        code = candidate_kernel(
            uniform_at(k0, k1, body, episode, STREAM_EPISODE, j),
            uniform_at(k0, k1, body, episode, STREAM_EPISODE, j + 1),
            uniform_at(k0, k1, body, episode, STREAM_EPISODE, j + 2),
            scfg,
            P,
            pot,
            table_code,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            cand,
        )
        if code == REJECT or code == UNSURE:
            continue
        used = j + 3
        for i in range(5):
            tg[i] = cand[i]
        tg[5] = cand[9]
        for i in range(m):
            uu[i] = uniform_at(k0, k1, body, episode, STREAM_EPISODE, used + i)
        if ball:
            ball_state_kernel(uu, scfg[14], scfg[15], cand[0], cand[1], cand[2], cand[3], cand[4], P[0], P[2], y)
        elif m > 0:
            initial_state_kernel(uu, scfg[6], scfg[7] != 0.0, cand[0], cand[1], cand[2], cand[3], cand[4], y)
        return used + m
    return NO_TARGET


def reset_body(
    b,
    k0,
    k1,
    write_info,
    Y,
    T,
    OBS,
    INFO,
    I,
    ENDS,
    P,
    kcfg,
    scfg,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    y,
    tg,
    pot,
    table_code,
    cand,
    uu,
    yout,
    a2,
    terms,
    sc,
    vel,
    force,
):
    """Reset body ``b``: its next episode's draws (:func:`draw_episode`; its episode count ``I[1, b]`` advances),
    its clock to 0, its observation into ``OBS[b]`` (:func:`~flatbody_env.env.kernels.post_step` of the start,
    as the CPU env's reset); with ``write_info`` also its distance, energy and |s|² into ``INFO[7:10, b]``.
    Returns 0, :data:`ERR_NO_TARGET` (the body is left as it was) or :data:`ERR_START`."""
    episode = I[1, b]
    I[1, b] = episode + 1
    if (
        draw_episode(
            k0,
            k1,
            b,
            episode,
            scfg,
            P,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            y,
            tg,
            pot,
            table_code,
            cand,
            uu,
        )
        == NO_TARGET
    ):
        return ERR_NO_TARGET
    for i in range(11):
        Y[i, b] = y[i]
    for i in range(4):
        T[i, b] = tg[i]
    I[0, b] = 0
    ENDS[2, b] = 0
    post_step(y, y, 0, a2[0], 0, T[:, b], kcfg, P, yout, OBS[b], terms, sc, vel, force)
    if write_info:
        INFO[7, b] = sc[0]
        INFO[8, b] = sc[1]
        INFO[9, b] = sc[2]
        INFO[10, b] = 0.0
        INFO[11, b] = 0.0
    return ERR_START if sc[3] != 0.0 else 0


def stagger_body(b, k0, k1, max_steps, I):
    """Body ``b``'s clock at a uniform step in [0, ``max_steps``) (stream :data:`STREAM_CLOCK`, its episode count)."""
    u = uniform_at(k0, k1, b, I[1, b], STREAM_CLOCK, 0)
    I[0, b] = min(int(u * max_steps), max_steps - 1)


# --------------------------------------------------------------------------------------------- step
def step_body(
    b,
    kind,
    coeffs,
    A,
    Y,
    T,
    OBS,
    FINAL,
    INFO,
    I,
    ENDS,
    P,
    kcfg,
    scfg,
    limits,
    mask,
    dt,
    h,
    rtol,
    atol,
    energy_tol,
    max_steps,
    same_step,
    k0,
    k1,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
    y,
    u,
    u2,
    out,
    K,
    ynew,
    ytmp,
    vel,
    force,
    f,
    counters,
    yout,
    a2,
    terms,
    sc,
    tg,
    pot,
    table_code,
    cand,
    uu,
):
    """Body ``b``'s environment step (module docstring for the arrays), as :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`'s
    step does it for that body: a body whose reset is pending (NEXT_STEP) is reset (reward 0, not ended); else its
    action ``A[b]`` is clipped and scaled, the integrator advances it, :func:`~flatbody_env.env.kernels.post_step` keeps or
    rejects the new state, observes and scores; its clock advances and truncates at ``max_steps``; in SAME_STEP mode
    (``same_step``) a body whose episode ended is reset at once (its last observation into ``FINAL[b]``), else its
    reset is marked pending. Work: ``u`` (4,), ``u2`` (4, 1), ``a2`` (1, 4), ``K`` (13, 11), ``counters`` (4,) int64 (the
    last entry: the step's budget of RHS evaluations, :data:`~flatbody_env.physics.validation.ENV_STEP_MAX_NFEV`, set by the caller),
    ``terms`` (6,), ``sc`` (4,), ``tg`` (6,), ``pot`` (7, 4), ``table_code`` (1,) int64, ``cand`` (10,), ``uu`` (12,),
    the others (11,), ``vel`` (7,), ``force`` (4,). Returns 0 or an error code (:data:`ERR_ACTION`: the body is left
    untouched)."""
    if ENDS[2, b] != 0:  # NEXT_STEP: the step after the end resets this body
        for i in range(7):
            INFO[i, b] = 0.0
        I[2, b] = 0
        I[3, b] = 0
        ENDS[0, b] = 0
        ENDS[1, b] = 0
        return reset_body(
            b,
            k0,
            k1,
            True,
            Y,
            T,
            OBS,
            INFO,
            I,
            ENDS,
            P,
            kcfg,
            scfg,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            y,
            tg,
            pot,
            table_code,
            cand,
            uu,
            yout,
            a2,
            terms,
            sc,
            vel,
            force,
        )
    n_act = A.shape[1]
    if not controls_batch(A[b : b + 1], mask, limits, a2, u2):
        return ERR_ACTION
    for i in range(4):
        u[i] = u2[i, 0]
    for i in range(11):
        y[i] = Y[i, b]
    counters[0] = 0
    counters[1] = 0
    counters[2] = 0
    status = env_step_into(
        kind, coeffs, y, u, P, dt, h, rtol, atol, energy_tol, out, K, ynew, ytmp, vel, force, f, counters
    )
    ended = post_step(y, out, status, a2[0], n_act, T[:, b], kcfg, P, yout, OBS[b], terms, sc, vel, force)
    for i in range(11):
        Y[i, b] = yout[i]
    steps = I[0, b] + 1
    I[0, b] = steps
    I[2, b] = status
    I[3, b] = counters[0]
    truncated = 1 if (steps >= max_steps and ended == 0) else 0
    reward = 0.0
    for i in range(6):
        reward += terms[i]
        INFO[1 + i, b] = terms[i]
    INFO[0, b] = reward
    for i in range(4):
        INFO[7 + i, b] = sc[i]
    INFO[11, b] = steps * dt
    ENDS[0, b] = ended
    ENDS[1, b] = truncated
    if ended == 0 and truncated == 0:
        return 0
    if same_step == 0:
        ENDS[2, b] = 1
        return 0
    for i in range(OBS.shape[1]):
        FINAL[b, i] = OBS[b, i]
    return reset_body(
        b,
        k0,
        k1,
        False,
        Y,
        T,
        OBS,
        INFO,
        I,
        ENDS,
        P,
        kcfg,
        scfg,
        grid,
        rate,
        margin,
        invalid,
        edge_lo,
        edge_hi,
        refined,
        fine_rate,
        fine_margin,
        y,
        tg,
        pot,
        table_code,
        cand,
        uu,
        yout,
        a2,
        terms,
        sc,
        vel,
        force,
    )


# --------------------------------------------------------------------------------------------- CPU loops
def step_lanes(
    kind,
    coeffs,
    A,
    Y,
    T,
    OBS,
    FINAL,
    INFO,
    I,
    ENDS,
    FLAGS,
    P,
    kcfg,
    scfg,
    limits,
    mask,
    dt,
    h,
    rtol,
    atol,
    energy_tol,
    max_steps,
    same_step,
    k0,
    k1,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
):
    """:func:`step_body` for every body, one after another (the CPU side of the CUDA kernel of
    :func:`flatbody_env.integrators.cuda.env_step` with ``task=``)."""
    y, u, out, ynew, ytmp, f, yout = (
        np.empty(11),
        np.empty(4),
        np.empty(11),
        np.empty(11),
        np.empty(11),
        np.empty(11),
        np.empty(11),
    )
    u2, a2, K = np.empty((4, 1)), np.zeros((1, 4)), np.empty((13, 11))
    vel, force, counters = np.empty(7), np.empty(4), np.zeros(4, np.int64)
    counters[3] = (
        ENV_STEP_MAX_NFEV  # each body's budget of RHS evaluations per step, as FlatBodyVectorEnv's (DOP853 checks it)
    )
    terms, sc, tg, pot, table_code, cand, uu = (
        np.empty(6),
        np.empty(4),
        np.empty(6),
        np.empty((7, 4)),
        np.zeros(1, np.int64),
        np.empty(10),
        np.empty(12),
    )
    for b in range(Y.shape[1]):
        err = step_body(
            b,
            kind,
            coeffs,
            A,
            Y,
            T,
            OBS,
            FINAL,
            INFO,
            I,
            ENDS,
            P,
            kcfg,
            scfg,
            limits,
            mask,
            dt,
            h,
            rtol,
            atol,
            energy_tol,
            max_steps,
            same_step,
            k0,
            k1,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            y,
            u,
            u2,
            out,
            K,
            ynew,
            ytmp,
            vel,
            force,
            f,
            counters,
            yout,
            a2,
            terms,
            sc,
            tg,
            pot,
            table_code,
            cand,
            uu,
        )
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def reset_lanes(
    MASK,
    stagger,
    Y,
    T,
    OBS,
    INFO,
    I,
    ENDS,
    FLAGS,
    P,
    kcfg,
    scfg,
    max_steps,
    k0,
    k1,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
):
    """:func:`reset_body` for the bodies with ``MASK[b]`` set (then :func:`stagger_body` with ``stagger``), one after another."""
    y, yout = np.empty(11), np.empty(11)
    a2 = np.zeros((1, 4))
    vel, force = np.empty(7), np.empty(4)
    terms, sc, tg, pot, table_code, cand, uu = (
        np.empty(6),
        np.empty(4),
        np.empty(6),
        np.empty((7, 4)),
        np.zeros(1, np.int64),
        np.empty(10),
        np.empty(12),
    )
    for b in range(Y.shape[1]):
        if MASK[b] != 0:
            err = reset_body(
                b,
                k0,
                k1,
                True,
                Y,
                T,
                OBS,
                INFO,
                I,
                ENDS,
                P,
                kcfg,
                scfg,
                grid,
                rate,
                margin,
                invalid,
                edge_lo,
                edge_hi,
                refined,
                fine_rate,
                fine_margin,
                y,
                tg,
                pot,
                table_code,
                cand,
                uu,
                yout,
                a2,
                terms,
                sc,
                vel,
                force,
            )
            ENDS[0, b] = 0
            ENDS[1, b] = 0
            if stagger != 0:
                stagger_body(b, k0, k1, max_steps, I)
            if err != 0:
                FLAGS[0] = err
                FLAGS[1] = b


# --------------------------------------------------------------------------------------------- CUDA kernels
cuda = None
"""numba.cuda in the kernels' globals (bound by :func:`flatbody_env.integrators.cuda.kernel` when it compiles them)."""


def _step_kernel(
    kind,
    coeffs,
    A,
    Y,
    T,
    OBS,
    FINAL,
    INFO,
    I,
    ENDS,
    FLAGS,
    P,
    kcfg,
    scfg,
    limits,
    mask,
    dt,
    h,
    rtol,
    atol,
    energy_tol,
    max_steps,
    same_step,
    k0,
    k1,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
):
    """One thread per body: :func:`step_body` with local work arrays (the CUDA side of :func:`step_lanes`)."""
    b = cuda.grid(1)
    if b < Y.shape[1]:
        y = cuda.local.array(11, float64)
        u = cuda.local.array(4, float64)
        u2 = cuda.local.array((4, 1), float64)
        out = cuda.local.array(11, float64)
        K = cuda.local.array((13, 11), float64)
        ynew = cuda.local.array(11, float64)
        ytmp = cuda.local.array(11, float64)
        vel = cuda.local.array(7, float64)
        force = cuda.local.array(4, float64)
        f = cuda.local.array(11, float64)
        counters = cuda.local.array(4, int64)
        counters[3] = (
            ENV_STEP_MAX_NFEV  # the launch's work: at most this many RHS evaluations per body (a kernel has no clock)
        )
        yout = cuda.local.array(11, float64)
        a2 = cuda.local.array((1, 4), float64)
        for i in range(4):
            a2[0, i] = 0.0
        terms = cuda.local.array(6, float64)
        sc = cuda.local.array(4, float64)
        tg = cuda.local.array(6, float64)
        pot = cuda.local.array((7, 4), float64)
        table_code = cuda.local.array(1, int64)
        cand = cuda.local.array(10, float64)
        uu = cuda.local.array(12, float64)
        err = step_body(
            b,
            kind,
            coeffs,
            A,
            Y,
            T,
            OBS,
            FINAL,
            INFO,
            I,
            ENDS,
            P,
            kcfg,
            scfg,
            limits,
            mask,
            dt,
            h,
            rtol,
            atol,
            energy_tol,
            max_steps,
            same_step,
            k0,
            k1,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            y,
            u,
            u2,
            out,
            K,
            ynew,
            ytmp,
            vel,
            force,
            f,
            counters,
            yout,
            a2,
            terms,
            sc,
            tg,
            pot,
            table_code,
            cand,
            uu,
        )
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def _reset_kernel(
    MASK,
    stagger,
    Y,
    T,
    OBS,
    INFO,
    I,
    ENDS,
    FLAGS,
    P,
    kcfg,
    scfg,
    max_steps,
    k0,
    k1,
    grid,
    rate,
    margin,
    invalid,
    edge_lo,
    edge_hi,
    refined,
    fine_rate,
    fine_margin,
):
    """One thread per body: :func:`reset_body` where ``MASK[b]`` is set (the CUDA side of :func:`reset_lanes`)."""
    b = cuda.grid(1)
    if b < Y.shape[1] and MASK[b] != 0:
        y = cuda.local.array(11, float64)
        yout = cuda.local.array(11, float64)
        vel = cuda.local.array(7, float64)
        force = cuda.local.array(4, float64)
        a2 = cuda.local.array((1, 4), float64)
        for i in range(4):
            a2[0, i] = 0.0
        terms = cuda.local.array(6, float64)
        sc = cuda.local.array(4, float64)
        tg = cuda.local.array(6, float64)
        pot = cuda.local.array((7, 4), float64)
        table_code = cuda.local.array(1, int64)
        cand = cuda.local.array(10, float64)
        uu = cuda.local.array(12, float64)
        err = reset_body(
            b,
            k0,
            k1,
            True,
            Y,
            T,
            OBS,
            INFO,
            I,
            ENDS,
            P,
            kcfg,
            scfg,
            grid,
            rate,
            margin,
            invalid,
            edge_lo,
            edge_hi,
            refined,
            fine_rate,
            fine_margin,
            y,
            tg,
            pot,
            table_code,
            cand,
            uu,
            yout,
            a2,
            terms,
            sc,
            vel,
            force,
        )
        ENDS[0, b] = 0
        ENDS[1, b] = 0
        if stagger != 0:
            stagger_body(b, k0, k1, max_steps, I)
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def _restart_kernel(MASK, I):
    """Episode counts of the masked bodies back to 0 (a reset with a seed)."""
    b = cuda.grid(1)
    if b < I.shape[1] and MASK[b] != 0:
        I[1, b] = 0


# --------------------------------------------------------------------------------------------- host side
def unsupported(p) -> str | None:
    """Why the env ``p`` (a :class:`~flatbody_env.env.env.FlatBodyEnv`) cannot run on these kernels, or None."""
    from flatbody_env.integrators.batch_solve import KIND

    task, st = p.task, p.stepper
    if not getattr(st, "compiled", False) or getattr(st, "carries_rotation", False) or st.method not in KIND:
        return f"integrator: {st.method!r} has no batch kernel (use one of {', '.join(KIND)})"
    if task.varies_body or task.extra_reward_names or task.observation_extra_names or not task.compiled_resets:
        return f"task: {type(task).__name__} draws or scores outside the device kernels (FlatBody-v0's task and options only)"
    if p.custom_potential is not None:
        return "potential: a custom (Python) potential cannot run on the device"
    sampler = p.sampler
    if not sampler.applies or sampler.cfg[5] == 0.0:
        return "task: its resets need the exact settling-rate test (no shipped table applies to this body, limits or ranges)"
    return None


def _seed_key(seed) -> tuple[int, int]:
    """The Philox key (two 32-bit words) of ``seed`` (None: fresh entropy), through numpy's ``SeedSequence``."""
    words = np.random.SeedSequence(seed).generate_state(2, np.uint32)
    return int(words[0]), int(words[1])


class DeviceBatch:
    """N bodies of an env on one backend: the arrays of the module docstring, reset and stepped by this module's kernels.

    ``backend="cpu"``: numpy arrays and the compiled loops :func:`step_lanes`, :func:`reset_lanes`;
    ``"cuda"``: device arrays and :func:`flatbody_env.integrators.cuda.env_step` with ``task=`` (one launch per
    step). ``alloc(shape, dtype)`` makes the batch's arrays (default numpy zeros, or numba device arrays on
    CUDA; :class:`~flatbody_env.env.torch_vector_env.FlatBodyTorchVectorEnv` passes torch tensors' views).
    ``p`` is the :class:`~flatbody_env.env.env.FlatBodyEnv` whose configuration all bodies share.
    """

    def __init__(
        self,
        p,
        num_envs: int,
        max_episode_steps: int,
        *,
        same_step: bool = True,
        backend: str = "cpu",
        alloc=None,
        threads_per_block: int | None = None,
    ) -> None:
        from flatbody_env.integrators.batch_solve import KIND

        why = unsupported(p)
        if why is not None:
            raise ValueError(why)
        if backend not in ("cpu", "cuda"):
            raise ValueError(f"backend: must be 'cpu' or 'cuda', got {backend!r}")
        self.p, self.num_envs, self.max_episode_steps, self.same_step, self.backend = (
            p,
            int(num_envs),
            int(max_episode_steps),
            bool(same_step),
            backend,
        )
        st = p.stepper
        self.method = st.method
        self.kind, coeffs = KIND[st.method]
        self.scalars = (float(p.dt), float(st.h), float(st.rtol), float(st.atol), float(st.energy_tol))
        n = self.num_envs
        if backend == "cuda":
            from flatbody_env.integrators import cuda as _cuda

            self._cuda = _cuda
            dev = _cuda.require()
            self._put = dev.to_device
            if alloc is None:

                def alloc(shape, dtype):
                    return dev.to_device(np.zeros(shape, dtype))

            self.threads_per_block = threads_per_block or _cuda.THREADS_PER_BLOCK
        else:
            self._put = np.ascontiguousarray
            alloc = alloc or (lambda shape, dtype: np.zeros(shape, dtype))
        sampler = p.sampler
        put = self._put
        self.coeffs = put(np.ascontiguousarray(coeffs, dtype=np.float64))
        self.P = put(np.ascontiguousarray(p.kernel_params, dtype=np.float64))
        self.kcfg = put(np.ascontiguousarray(p.kernel_config, dtype=np.float64))
        self.scfg = put(np.ascontiguousarray(sampler.cfg, dtype=np.float64))
        self.limits = put(np.ascontiguousarray(p.limits, dtype=np.float64))
        self.mask = put(p.mask.astype(np.uint8))
        self.table = tuple(put(np.ascontiguousarray(a)) for a in sampler.table)
        self.n_act = int(p.action_space.shape[0])
        self.Y = alloc((11, n), np.float64)
        self.T = alloc((4, n), np.float64)
        self.OBS = alloc((n, p.observation_size), np.float32)
        self.FINAL = alloc((n, p.observation_size), np.float32)
        self.INFO = alloc((INFO_ROWS, n), np.float64)
        self.I = alloc((I_ROWS, n), np.int64)
        self.ENDS = alloc((ENDS_ROWS, n), np.uint8)
        self.FLAGS = alloc((2,), np.int64)
        self._all = put(np.ones(n, np.uint8))
        self.key = _seed_key(None)
        """The Philox key (two 32-bit words) of the last ``reset(seed=)``."""

    # --- launches ------------------------------------------------------------------------------------------
    def reset(self, seed=None, mask=None, stagger: bool = False, check: bool = True) -> None:
        """Reset every body (``mask`` None) or the masked ones (a (N,) uint8/bool array on the batch's backend); a seed
        (an int) sets the key and restarts the reset bodies' episode counts, so their draws are those of that seed."""
        MASK = self._all if mask is None else mask
        if seed is not None:
            self.key = _seed_key(seed)
            if self.backend == "cpu":
                self.I[1, np.asarray(MASK).astype(bool)] = 0
            else:
                blocks, threads = self._cuda._blocks(self.num_envs, self.threads_per_block)
                self.cuda_kernels()[2][blocks, threads](MASK, self.I)
        args = (
            MASK,
            1 if stagger else 0,
            self.Y,
            self.T,
            self.OBS,
            self.INFO,
            self.I,
            self.ENDS,
            self.FLAGS,
            self.P,
            self.kcfg,
            self.scfg,
            self.max_episode_steps,
            self.key[0],
            self.key[1],
            *self.table,
        )
        if self.backend == "cpu":
            _cpu()[1](*args)
        else:
            blocks, threads = self._cuda._blocks(self.num_envs, self.threads_per_block)
            self.cuda_kernels()[1][blocks, threads](*args)
        if check:
            self.check()

    def cuda_kernels(self) -> tuple:
        """The CUDA step, reset and restart kernels (compiled once per process by :func:`flatbody_env.integrators.cuda.kernel`)."""
        return tuple(self._cuda.kernel(k) for k in (_step_kernel, _reset_kernel, _restart_kernel))

    def step(self, A, check: bool = True) -> None:
        """One env step of every body with actions ``A`` (N, n) (float32 or float64, on the batch's backend)."""
        if tuple(A.shape) != (self.num_envs, self.n_act):
            raise ValueError(f"actions: expected shape ({self.num_envs}, {self.n_act}), got {tuple(A.shape)}")
        dt, h, rtol, atol, etol = self.scalars
        if self.backend == "cpu":
            _cpu()[0](
                self.kind,
                self.coeffs,
                A,
                self.Y,
                self.T,
                self.OBS,
                self.FINAL,
                self.INFO,
                self.I,
                self.ENDS,
                self.FLAGS,
                self.P,
                self.kcfg,
                self.scfg,
                self.limits,
                self.mask,
                dt,
                h,
                rtol,
                atol,
                etol,
                self.max_episode_steps,
                1 if self.same_step else 0,
                self.key[0],
                self.key[1],
                *self.table,
            )
        else:
            self._cuda.env_step(
                self.method,
                self.Y,
                A,
                self.P,
                dt,
                h=h,
                rtol=rtol,
                atol=atol,
                energy_tol=etol,
                task=self,
                threads_per_block=self.threads_per_block,
            )
        if check:
            self.check()

    def check(self) -> None:
        """Raise the error a launch flagged (``FLAGS``; a device-to-host copy of two integers on CUDA), and clear it."""
        flags = self.FLAGS if self.backend == "cpu" else self.FLAGS.copy_to_host()
        code, body = int(flags[0]), int(flags[1])
        if code == 0:
            return
        if self.backend == "cpu":
            self.FLAGS[:] = 0
        else:
            self.FLAGS.copy_to_device(np.zeros(2, np.int64))
        if code == ERR_ACTION:
            raise ValueError(
                f"actions: must be finite numbers in [-1, 1] (body {body} was not stepped; the bodies with finite "
                "actions were)"
            )
        if code == ERR_NO_TARGET:
            raise ValueError(self.p.task.no_target_message)
        raise ValueError(f"initial_noise: body {body}'s start lies outside the domain; lower initial_noise")

    def host(self, name: str) -> np.ndarray:
        """A copy of array ``name`` on the host."""
        a = getattr(self, name)
        return a.copy() if self.backend == "cpu" else a.copy_to_host()


_CPU: list = []


def _cpu():
    """The CPU loops, compiled on first use (:func:`~flatbody_env.integrators.jit.retarget`)."""
    if not _CPU:
        from flatbody_env.integrators.jit import retarget

        _CPU.extend([retarget(step_lanes), retarget(reset_lanes)])
    return _CPU


__all__ = [
    "ERR_ACTION",
    "ERR_NO_TARGET",
    "ERR_START",
    "STREAM_CLOCK",
    "STREAM_EPISODE",
    "DeviceBatch",
    "draw_episode",
    "philox4x32",
    "reset_body",
    "reset_lanes",
    "stagger_body",
    "step_body",
    "step_lanes",
    "uniform_at",
    "unsupported",
]
