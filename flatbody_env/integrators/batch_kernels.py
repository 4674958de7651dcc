"""One fused DOP853 environment step for N bodies in structure-of-arrays layout.

Plain-Python kernels over arrays, compiled with :func:`flatbody_env.integrators.jit.retarget`
(:data:`dop853_batch_env_step` is the compiled driver): no numpy allocation inside, no
``np.nextafter``, no per-lane branch in the stage loops — the same source can later be given a GPU
target. The physics is the physics layer's scalar right-hand side for J1 = J2,
:func:`flatbody_env.physics.equations.rhs_iso` (eqs. (44)–(49) of the paper; :func:`rhs_core` calls
it too), called per lane on scalars: with the body's parameters read once into scalars the lane loop
has no memory dependence, and numba (LLVM) turns it into SIMD instructions (``error_model="numpy"``:
no division checks; no fastmath, so each lane's arithmetic is the scalar kernel's, bit for bit).

The step. Every lane takes one DOP853 step of size h = dt (Hairer's coefficients, the same arithmetic in
the same order as :func:`flatbody_env.integrators.twopolar_kernels.dop853_env_step` with the first step
guessed as dt): 12 right-hand sides (the scalar kernel's 13th, f at the new state, only starts its next
step), the stages combined over their nonzero coefficients for the whole block at once, up to four
stages per pass (:func:`combine_lanes`; the sums were the larger half of the step's time when each stage
made its own pass over a sum kept in memory). Then each lane's embedded error estimate (scipy's
5th/3rd-order blend) and its state are checked. A lane whose step stands but whose state ends the
episode (non-finite, out of the chart: λ, μ, ϱ ≤ 0, λ − μ changing sign where it may not) gets the
scalar kernel's status at once, from :func:`~flatbody_env.integrators.twopolar_kernels.state_code` on
the lane's values. The lanes whose step is rejected (error ≥ 1) go on together
(:func:`dop853_redo_lanes`): fused attempts with a step size per lane, decided lane by lane by the
scalar kernel's step control, starting from the rejection, in blocks of :data:`REDO_BLOCK` lanes (the
same code compiled for that block size); a lane whose step would collapse goes to the scalar kernel. So
every lane's result, status and function count are bit for bit the scalar kernel's (compiled with the
same options, :data:`JIT_OPTIONS`): the vector env equals N single envs step for step.

Lanes are stepped in blocks of :data:`BLOCK` so that the stage array stays in the caches.

Arrays: ``Y``, ``OUT`` (11, N); ``U`` (4, N); ``P`` (9, 1) one body's kernel parameters or (9, N) each
lane's (J1 = J2 and one potential kind in every lane: a batch of bodies drawn per episode steps fused as
well); ``STATUS``, ``NFEV`` (N,) int64 (outputs; ``NFEV`` counts the scalar kernel's evaluations, 13 per
accepted single step); ``ERR`` (N,) the error norms; work: ``KS`` (12, 11, B), ``YT``, ``ACC``, ``HH``,
``A5``, ``A3`` (11, B), ``PB`` (9, B), ``E3S``, ``HB`` (B,) for blocks of B lanes (all flat), ``LANES``
(N,) int64, ``W`` (9, B), ``pl`` (9,) and the scalar kernel's work arrays — allocated once by the caller
(:class:`DOP853Batch`).
"""

from __future__ import annotations

import math

import numpy as np

from flatbody_env.integrators import twopolar_kernels as _tk
from flatbody_env.integrators.batch_solve import DOP853_KIND, NO_BUDGET, env_step_body
from flatbody_env.integrators.dop853_tableau import ERROR_E3, ERROR_E5, ERROR_J, STAGE_C, STAGE_J, STAGE_L
from flatbody_env.integrators.jit import retarget
from flatbody_env.physics.equations import rhs_iso
from flatbody_env.physics.potentials import potential_kernel

N = 11
BLOCK = 64
"""Lanes per block of the fused step (a compile-time constant: the block arrays are addressed at
constant offsets, and the stage array, 12 × 11 × BLOCK doubles, stays in the CPU caches)."""
S = N * BLOCK
"""Entries of one block array (component i of lane k at i·BLOCK + k)."""
REDO_BLOCK = 8
"""Lanes per block when rejected lanes go on (:func:`dop853_redo_lanes`): a few lanes per env step, so
a small block wastes little work on padding lanes."""


def rhs_lanes(X, U, P, F):
    """F[i·BLOCK + k] = component i of dy/dt of lane k of the block X (component i of lane k at
    X[i·BLOCK + k]) with controls U[j·BLOCK + k] and body parameters P[r·BLOCK + k] (the layout of
    :meth:`~flatbody_env.physics.body.Body.kernel_params` per lane), for J1 = J2 and one potential kind
    in every lane (the caller checks; the kind is read from lane 0).

    The physics is :func:`flatbody_env.physics.equations.rhs_iso` and
    :func:`flatbody_env.physics.potentials.potential_kernel` on scalars. Each array is addressed at
    constant offsets from its own start (``F`` is a view of the stage array, not an array and a run-time
    offset: with an offset of unknown sign numba's negative-index wrap-around makes the store addresses
    non-affine and LLVM gives up vectorising), so the lane loop has no memory dependence and numba
    (LLVM) compiles it to SIMD instructions (4 lanes per AVX2 instruction; about twice the speed of the
    scalar loop). The potential's kind, a branch, is the same in every lane, so the branch stays outside
    the vector instructions.
    """
    kind = P[3 * BLOCK]
    for k in range(BLOCK):
        J = P[k]
        J3 = P[2 * BLOCK + k]
        c1 = P[4 * BLOCK + k]
        c2 = P[5 * BLOCK + k]
        a = P[6 * BLOCK + k]
        b = P[7 * BLOCK + k]
        conv = P[8 * BLOCK + k]
        lam = X[7 * BLOCK + k]
        mu = X[8 * BLOCK + k]
        rho = X[9 * BLOCK + k]
        v, gl, gm, gr = potential_kernel(kind, c1, c2, a, b, lam, mu, rho)
        (d0, d1, d2, d3, d4, d5, d6, d7, d8, d9, d10, w1, w2, w3, thd, ld, md, rd, f1, f2, f3) = rhs_iso(
            X[k],
            X[BLOCK + k],
            X[2 * BLOCK + k],
            X[3 * BLOCK + k],
            X[4 * BLOCK + k],
            X[5 * BLOCK + k],
            X[6 * BLOCK + k],
            lam,
            mu,
            rho,
            U[k],
            U[BLOCK + k],
            U[2 * BLOCK + k],
            U[3 * BLOCK + k],
            J,
            J3,
            conv,
            gl,
            gm,
            gr,
        )
        F[k] = d0
        F[BLOCK + k] = d1
        F[2 * BLOCK + k] = d2
        F[3 * BLOCK + k] = d3
        F[4 * BLOCK + k] = d4
        F[5 * BLOCK + k] = d5
        F[6 * BLOCK + k] = d6
        F[7 * BLOCK + k] = d7
        F[8 * BLOCK + k] = d8
        F[9 * BLOCK + k] = d9
        F[10 * BLOCK + k] = d10


def combine_lanes(KS, Y, HH, row, OUT, ACC):
    """OUT[x] = Y[x] + HH[x] · Σ_q KS[J_q·S + x] · C_q for all x < S = 11·BLOCK, over the nonzero terms
    (J_q, C_q) of row ``row`` of :data:`~flatbody_env.integrators.dop853_tableau.STAGE_J` /
    ``STAGE_C`` in increasing J_q — each lane's and component's sum in the scalar kernel's order.

    Component i of lane k sits at x = i·BLOCK + k in every array, so one flat loop covers the whole
    block. Up to four terms are added per pass over ``ACC`` (S,), so the sum is read and written once
    per four stages rather than once per stage."""
    n = STAGE_L[row]
    for x in range(S):
        ACC[x] = 0.0
    q = 0
    while q < n:
        m = min(4, n - q)
        j0 = STAGE_J[row, q]
        j1 = STAGE_J[row, q + 1] if m > 1 else j0
        j2 = STAGE_J[row, q + 2] if m > 2 else j0
        j3 = STAGE_J[row, q + 3] if m > 3 else j0
        c0 = STAGE_C[row, q]
        c1 = STAGE_C[row, q + 1] if m > 1 else 0.0
        c2 = STAGE_C[row, q + 2] if m > 2 else 0.0
        c3 = STAGE_C[row, q + 3] if m > 3 else 0.0
        K0 = KS[j0 * S : (j0 + 1) * S]
        K1 = KS[j1 * S : (j1 + 1) * S]
        K2 = KS[j2 * S : (j2 + 1) * S]
        K3 = KS[j3 * S : (j3 + 1) * S]
        if m == 4:
            for x in range(S):
                ACC[x] = ACC[x] + K0[x] * c0 + K1[x] * c1 + K2[x] * c2 + K3[x] * c3
        elif m == 3:
            for x in range(S):
                ACC[x] = ACC[x] + K0[x] * c0 + K1[x] * c1 + K2[x] * c2
        elif m == 2:
            for x in range(S):
                ACC[x] = ACC[x] + K0[x] * c0 + K1[x] * c1
        else:
            for x in range(S):
                ACC[x] = ACC[x] + K0[x] * c0
        q += m
    for x in range(S):
        OUT[x] = Y[x] + HH[x] * ACC[x]


def dop853_lanes(Y, U, P, H, rtol, atol, OUT, KS, YT, E5S, E3S, ACC, HH, A5, A3):
    """One DOP853 step of size ``H[k]`` for each lane k of a block; OUT receives y + h Σ b_j k_j,
    E5S the error norm (scipy's ``_estimate_error_norm``) of each lane. Flat block arrays: component
    i of lane k at [i·BLOCK + k] (the body parameters ``P`` too, :func:`rhs_lanes`), stage j's component
    i at KS[(j·11 + i)·BLOCK + k] (KS: 12 stages).
    The lane index is the innermost loop; each lane's sums keep the scalar kernel's order
    (:func:`combine_lanes`). The scalar kernel's 13th evaluation, f at the new state, is its next
    step's first stage and enters no error estimate: a fused step, whose next step starts with new
    controls, skips it. Work: ``E3S`` (BLOCK,), ``ACC``, ``HH``, ``A5``, ``A3`` (11·BLOCK,)."""
    for i in range(11):
        for k in range(BLOCK):
            HH[i * BLOCK + k] = H[k]
    rhs_lanes(Y, U, P, KS[0:S])
    for s in range(1, 12):
        combine_lanes(KS, Y, HH, s, YT, ACC)
        rhs_lanes(YT, U, P, KS[s * S : (s + 1) * S])
    combine_lanes(KS, Y, HH, 12, OUT, ACC)
    for x in range(S):
        A5[x] = 0.0
        A3[x] = 0.0
    n = ERROR_J.shape[0]
    q = 0
    while q < n:  # the error sums, four stages per pass (as in combine_lanes), both estimates at once
        if n - q >= 4:
            K0 = KS[ERROR_J[q] * S : (ERROR_J[q] + 1) * S]
            K1 = KS[ERROR_J[q + 1] * S : (ERROR_J[q + 1] + 1) * S]
            K2 = KS[ERROR_J[q + 2] * S : (ERROR_J[q + 2] + 1) * S]
            K3 = KS[ERROR_J[q + 3] * S : (ERROR_J[q + 3] + 1) * S]
            a0, a1, a2, a3 = ERROR_E5[q], ERROR_E5[q + 1], ERROR_E5[q + 2], ERROR_E5[q + 3]
            b0, b1, b2, b3 = ERROR_E3[q], ERROR_E3[q + 1], ERROR_E3[q + 2], ERROR_E3[q + 3]
            for x in range(S):
                k0 = K0[x]
                k1 = K1[x]
                k2 = K2[x]
                k3 = K3[x]
                A5[x] = A5[x] + k0 * a0 + k1 * a1 + k2 * a2 + k3 * a3
                A3[x] = A3[x] + k0 * b0 + k1 * b1 + k2 * b2 + k3 * b3
            q += 4
        else:
            K0 = KS[ERROR_J[q] * S : (ERROR_J[q] + 1) * S]
            a0 = ERROR_E5[q]
            b0 = ERROR_E3[q]
            for x in range(S):
                A5[x] = A5[x] + K0[x] * a0
                A3[x] = A3[x] + K0[x] * b0
            q += 1
    for x in range(S):
        sc = atol + max(abs(Y[x]), abs(OUT[x])) * rtol
        a5 = A5[x] / sc
        a3 = A3[x] / sc
        A5[x] = a5 * a5
        A3[x] = a3 * a3
    for k in range(BLOCK):
        E5S[k] = 0.0
        E3S[k] = 0.0
    for i in range(11):  # each lane's norm summed over the components in order, as the scalar kernel does
        for k in range(BLOCK):
            E5S[k] += A5[i * BLOCK + k]
            E3S[k] += A3[i * BLOCK + k]
    for k in range(BLOCK):
        e5 = E5S[k]
        e3 = E3S[k]
        E5S[k] = 0.0 if (e5 == 0.0 and e3 == 0.0) else abs(H[k]) * e5 / math.sqrt((e5 + 0.01 * e3) * 11)


def dop853_batch_env_step(
    Y,
    U,
    P,
    dt,
    rtol,
    atol,
    energy_tol,
    OUT,
    STATUS,
    NFEV,
    ERR,
    YB,
    UB,
    OB,
    PB,
    KS,
    YT,
    EB,
    E3S,
    ACC,
    HH,
    A5,
    A3,
    HB,
    LANES,
    W,
    yl,
    ul,
    pl,
    K1,
    ynew,
    ytmp,
    f,
    out1,
    vel,
    force,
    counters,
):
    """One env step of DOP853 (first step guess dt) for N lanes: the fused step on blocks of
    :data:`BLOCK` lanes copied into the flat block arrays ``YB``, ``UB``, ``OB`` (the last block
    padded with its first lane), then the lanes it cannot accept redone by :func:`dop853_redo_lanes`
    (module docstring). ``energy_tol`` < inf hands every lane to the scalar kernel, and so does a budget
    of RHS evaluations per lane (``counters[3]``, :data:`FUSED_MAX_NFEV`) that the fused attempts could
    exceed; a lane the scalar kernel takes keeps that budget (the ``budget`` status past it)."""
    n = Y.shape[1]
    check_energy = energy_tol < np.inf or (counters.size > 3 and counters[3] < FUSED_MAX_NFEV)
    shared = P.shape[1] == 1
    if check_energy:
        for k in range(n):
            for r in range(9):
                pl[r] = P[r, 0 if shared else k]
            scalar_lane(
                k,
                DOP853_KIND,
                NO_COEFFS,
                Y,
                U,
                pl,
                dt,
                dt,
                rtol,
                atol,
                energy_tol,
                OUT,
                STATUS,
                NFEV,
                yl,
                ul,
                out1,
                K1,
                ynew,
                ytmp,
                vel,
                force,
                f,
                counters,
            )
        return
    for j in range(BLOCK):
        HB[j] = dt
        if shared:
            for r in range(9):
                PB[r * BLOCK + j] = P[r, 0]
    for start in range(0, n, BLOCK):
        m = min(BLOCK, n - start)
        if not shared:
            for r in range(9):
                for j in range(m):
                    PB[r * BLOCK + j] = P[r, start + j]
                for j in range(m, BLOCK):
                    PB[r * BLOCK + j] = P[r, start]
        for i in range(11):  # component by component: contiguous copies
            for j in range(m):
                YB[i * BLOCK + j] = Y[i, start + j]
            for j in range(m, BLOCK):
                YB[i * BLOCK + j] = Y[i, start]
        for i in range(4):
            for j in range(m):
                UB[i * BLOCK + j] = U[i, start + j]
            for j in range(m, BLOCK):
                UB[i * BLOCK + j] = U[i, start]
        dop853_lanes(YB, UB, PB, HB, rtol, atol, OB, KS, YT, EB, E3S, ACC, HH, A5, A3)
        for i in range(11):
            for j in range(m):
                OUT[i, start + j] = OB[i * BLOCK + j]
        for j in range(m):
            ERR[start + j] = EB[j]
            if EB[j] < 1.0:  # the step stands: the scalar kernel accepts it and reports the state it reached
                finite = True
                for i in range(11):
                    if not math.isfinite(OB[i * BLOCK + j]):
                        finite = False
                gap_sign = 1.0 if YB[7 * BLOCK + j] > YB[8 * BLOCK + j] else -1.0
                STATUS[start + j] = state_code(
                    finite,
                    OB[7 * BLOCK + j],
                    OB[8 * BLOCK + j],
                    OB[9 * BLOCK + j],
                    gap_sign,
                    not crossable(PB[j], PB[BLOCK + j], YB[2 * BLOCK + j], YB[3 * BLOCK + j], UB[2 * BLOCK + j]),
                )
                NFEV[start + j] = 13
    nl = 0
    for k in range(n):
        if not ERR[k] < 1.0:
            LANES[nl] = k
            nl += 1
    if nl > 0:
        dop853_redo_lanes(
            Y,
            U,
            P,
            dt,
            rtol,
            atol,
            LANES,
            nl,
            ERR,
            OUT,
            STATUS,
            NFEV,
            YB,
            UB,
            OB,
            PB,
            KS,
            YT,
            EB,
            E3S,
            ACC,
            HH,
            A5,
            A3,
            HB,
            W,
            yl,
            ul,
            pl,
            K1,
            ynew,
            ytmp,
            f,
            out1,
            vel,
            force,
            counters,
        )


MAX_ROUNDS = 64
"""Fused attempts per block of redone lanes before the lanes still unfinished go to the scalar kernel."""
FUSED_MAX_NFEV = 1 + 12 * (MAX_ROUNDS + 1)
"""The most RHS evaluations (the scalar kernel's count) a lane takes in the fused attempts: the first step
and :data:`MAX_ROUNDS` redone ones. With a smaller budget per lane every lane goes to the scalar kernel,
which checks the budget before every step; with this budget or more the fused attempts stay within it and
a lane handed to the scalar kernel runs with it from its start. Either way every lane's state, status and
count are the scalar kernel's with the same budget, bit for bit."""


def dop853_redo_lanes(
    Y,
    U,
    P,
    dt,
    rtol,
    atol,
    LANES,
    nl,
    ERR,
    OUT,
    STATUS,
    NFEV,
    YB,
    UB,
    OB,
    PB,
    KS,
    YT,
    EB,
    E3S,
    ACC,
    HH,
    A5,
    A3,
    HB,
    W,
    yl,
    ul,
    pl,
    K1,
    ynew,
    ytmp,
    f,
    out1,
    vel,
    force,
    counters,
):
    """The lanes ``LANES[:nl]``, whose single step h = dt was rejected with the error norms ``ERR``,
    over one env step with the scalar kernel's step control, fused.

    The scalar kernel (:func:`flatbody_env.integrators.twopolar_kernels.dop853_advance`) takes each
    lane from t = 0 to dt with steps it accepts or rejects by the error norm (factors
    0.9·err^(−1/8) in [0.2, 10], no growth right after a rejection, the last step cut at dt) and checks
    the state after every accepted step. Here up to BLOCK lanes (:data:`REDO_BLOCK` in the compiled
    driver) follow that same sequence together: every round computes one attempt of every unfinished lane (its own step size, one
    :func:`dop853_lanes` call; finished and padding lanes take a zero step that is thrown away), then
    applies the scalar kernel's decisions lane by lane; the first attempt is the fused step's (the
    same arithmetic), so the lanes start from its rejection. Every lane therefore ends with the scalar
    kernel's state, status and function count (1 + 12 per attempt), bit for bit; a lane whose step
    would collapse, or that is still unfinished after :data:`MAX_ROUNDS` rounds, is handed to the
    scalar kernel from its start.

    ``W`` (9, BLOCK) work: t, |h|, rejected, active, attempts, gap sign, check gap, new step, t_new;
    ``yl`` (11,) receives a lane's state for the status check.
    """
    shared = P.shape[1] == 1
    for start in range(0, nl, BLOCK):
        m = min(BLOCK, nl - start)
        for j in range(BLOCK):
            k = LANES[start + j] if j < m else LANES[start]
            for i in range(11):
                YB[i * BLOCK + j] = Y[i, k]
            for i in range(4):
                UB[i * BLOCK + j] = U[i, k]
            for r in range(9):
                PB[r * BLOCK + j] = P[r, 0 if shared else k]
            # the first attempt (h = dt) was the fused step's, rejected with the error ERR[k]: go on from there
            factor = _SAFETY * ERR[k] ** _ERROR_EXPONENT
            if not factor > _MIN_FACTOR:
                factor = _MIN_FACTOR
            W[0, j] = 0.0
            W[1, j] = dt * factor
            W[2, j] = 1.0
            W[3, j] = 1.0 if j < m else 0.0
            W[4, j] = 1.0
            W[5, j] = 1.0 if Y[7, k] > Y[8, k] else -1.0
            W[6, j] = 0.0 if crossable(PB[j], PB[BLOCK + j], Y[2, k], Y[3, k], U[2, k]) else 1.0
            W[7, j] = 0.0
            STATUS[k] = OK
        for _ in range(MAX_ROUNDS):
            active = 0
            for j in range(BLOCK):
                HB[j] = 0.0
                if W[3, j] == 0.0:
                    continue
                t = W[0, j]
                min_step = 10.0 * abs(next_up(t) - t)
                if W[7, j] != 0.0:  # a new step starts at t
                    if W[1, j] < min_step:
                        W[1, j] = min_step
                    W[2, j] = 0.0
                    W[7, j] = 0.0
                if W[1, j] < min_step:  # the step would collapse: the scalar kernel decides
                    W[3, j] = -1.0
                    continue
                t_new = t + W[1, j]
                if t_new > dt:
                    t_new = dt
                h = t_new - t
                W[1, j] = abs(h)
                W[8, j] = t_new
                HB[j] = h
                active += 1
            if active == 0:
                break
            dop853_lanes(YB, UB, PB, HB, rtol, atol, OB, KS, YT, EB, E3S, ACC, HH, A5, A3)
            for j in range(BLOCK):
                if W[3, j] != 1.0:
                    continue
                W[4, j] += 1.0
                err = EB[j]
                if err < 1.0:
                    if err == 0.0:
                        factor = _MAX_FACTOR
                    else:
                        factor = min(_MAX_FACTOR, _SAFETY * err**_ERROR_EXPONENT)
                    if W[2, j] != 0.0:
                        factor = min(1.0, factor)
                    W[1, j] *= factor
                    W[0, j] = W[8, j]
                    for i in range(11):
                        YB[i * BLOCK + j] = OB[i * BLOCK + j]
                        yl[i] = OB[i * BLOCK + j]
                    st = state_status(yl, W[5, j], W[6, j] != 0.0)
                    if st != OK:
                        STATUS[LANES[start + j]] = st
                        W[3, j] = 0.0
                    elif W[0, j] >= dt:
                        W[3, j] = 0.0
                    else:
                        W[7, j] = 1.0
                else:
                    factor = _SAFETY * err**_ERROR_EXPONENT
                    if not factor > _MIN_FACTOR:
                        factor = _MIN_FACTOR
                    W[1, j] *= factor
                    W[2, j] = 1.0
        for j in range(m):
            k = LANES[start + j]
            if W[3, j] != 0.0:  # collapsed or unfinished: the scalar kernel from the start
                for r in range(9):
                    pl[r] = P[r, 0 if shared else k]
                scalar_lane(
                    k,
                    DOP853_KIND,
                    NO_COEFFS,
                    Y,
                    U,
                    pl,
                    dt,
                    dt,
                    rtol,
                    atol,
                    np.inf,
                    OUT,
                    STATUS,
                    NFEV,
                    yl,
                    ul,
                    out1,
                    K1,
                    ynew,
                    ytmp,
                    vel,
                    force,
                    f,
                    counters,
                )
                continue
            for i in range(11):
                OUT[i, k] = YB[i * BLOCK + j]
            NFEV[k] = 1 + 12 * int(W[4, j])


scalar_lane = env_step_body
"""A lane by the scalar kernel from its start (first step guess dt): the per-body environment step of
:mod:`~flatbody_env.integrators.batch_solve` (compiled with the same options)."""
NO_COEFFS = _tk.STRANG
"""(the fixed-step coefficients :func:`scalar_lane` takes; unused by DOP853)"""
state_status = _tk._state_status
state_code = _tk.state_code
crossable = _tk.crossable
next_up = _tk.next_up
OK = _tk.OK
_SAFETY = _tk._SAFETY
_MIN_FACTOR = _tk._MIN_FACTOR
_MAX_FACTOR = _tk._MAX_FACTOR
_ERROR_EXPONENT = _tk._ERROR_EXPONENT


# compiled with every callee re-bound recursively (the physics kernels included); the rejected lanes go on
# in blocks of REDO_BLOCK lanes: the same code with BLOCK (and S) re-bound
dop853_batch_env_step_c = retarget(
    dop853_batch_env_step, dop853_redo_lanes=retarget(dop853_redo_lanes, BLOCK=REDO_BLOCK, S=N * REDO_BLOCK)
)
"""Compiled :func:`dop853_batch_env_step`."""


class DOP853Batch:
    """Work arrays for :func:`dop853_batch_env_step` at batch size N, and the call (picklable)."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self._alloc()

    def _alloc(self) -> None:
        B, Sz = BLOCK, S
        self.work = (
            np.empty(self.n),
            np.empty(Sz),
            np.empty(4 * B),
            np.empty(Sz),
            np.empty(9 * B),
            np.empty(12 * Sz),
            np.empty(Sz),
            np.empty(B),
            np.empty(B),
            np.empty(Sz),
            np.empty(Sz),
            np.empty(Sz),
            np.empty(Sz),
            np.empty(B),
            np.empty(self.n, np.int64),
            np.empty((9, B)),
            np.empty(N),
            np.empty(4),
            np.empty(9),
            np.empty((13, N)),
            np.empty(N),
            np.empty(N),
            np.empty(N),
            np.empty(N),
            np.empty(7),
            np.empty(4),
            np.zeros(4, np.int64),
        )  # counters: [nfev, steps, rejected, budget of nfev per lane]

    def __getstate__(self):
        return {"n": self.n}

    def __setstate__(self, state):
        self.n = state["n"]
        self._alloc()

    def __call__(self, Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, max_nfev: int = NO_BUDGET) -> None:
        """``P``: the body's kernel parameters (9,), or each lane's (9, N) (a batch of bodies, e.g. one drawn per
        episode); ``max_nfev``: each lane's budget of RHS evaluations in this step (``budget`` status past it)."""
        P = np.asarray(P)
        if P.ndim == 1:
            P = P.reshape(-1, 1)
        if P.ndim != 2 or P.shape[0] != 9 or P.shape[1] not in (1, Y.shape[1]):
            raise ValueError(f"P: expected shape (9,) or (9, {Y.shape[1]}), got {P.shape}")
        if P.shape[1] == 1:
            if P[0, 0] != P[1, 0]:
                raise ValueError("P: the fused batch step needs J1 = J2")
        elif not (np.array_equal(P[0], P[1]) and (P[3] == P[3, 0]).all()):
            raise ValueError("P: the fused batch step needs J1 = J2 and one potential kind in every lane")
        if Y.shape[1] != self.n:
            self.n = Y.shape[1]
            self._alloc()
        self.work[-1][3] = max_nfev
        dop853_batch_env_step_c(Y, U, P, dt, rtol, atol, energy_tol, OUT, STATUS, NFEV, *self.work)


__all__ = [
    "BLOCK",
    "DOP853Batch",
    "FUSED_MAX_NFEV",
    "MAX_ROUNDS",
    "REDO_BLOCK",
    "S",
    "combine_lanes",
    "dop853_batch_env_step",
    "dop853_batch_env_step_c",
    "dop853_lanes",
    "dop853_redo_lanes",
    "rhs_lanes",
]
