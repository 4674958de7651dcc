"""The environment transition, once: a body's reset draw, step, observation, reward and termination as
plain-Python per-body functions, compiled for the CPU and for CUDA from this one source.

gymnax and brax write an environment as a pure transition of (state, action, key); batching is a
layer on top. Here the transition is :func:`step_body` (and :func:`reset_body` for a reset): one body
``b`` of a batch, read from and written to the batch's arrays in structure-of-arrays layout. Every face
of the environment runs these functions — the single :class:`~flatbody_env.env.env.FlatBodyEnv` (a batch
of one), :class:`~flatbody_env.env.vector_env.FlatBodyVectorEnv`, the torch face on the CPU and on CUDA —
through :mod:`flatbody_env.env.core`, which holds a batch's arrays and launches them: numba compiles
them for the CPU (:func:`~flatbody_env.integrators.jit.retarget`: :func:`step_lanes`, :func:`reset_lanes`,
:func:`finish_lanes`, loops over the bodies) and, from the same source, for CUDA (one thread per body,
one launch per env step). They call the physics and the task's kernels and restate none of them:
:func:`~flatbody_env.env.kernels.post_step` (domain, kept state, observation, distance, the v0 reward
terms, energy), :func:`~flatbody_env.integrators.twopolar_kernels.env_step_into` (the integrator),
:func:`~flatbody_env.env.sampling.candidate_kernel` (target shape, the settling-rate table, stability),
:func:`~flatbody_env.env.sampling.initial_state_kernel` and :func:`~flatbody_env.env.sampling.ball_state_kernel`
(starts).

Arrays of a batch of N bodies
-----------------------------
* ``S`` (:data:`S_ROWS`, N) float64: the state y (rows :data:`Y0`…+10), the target (λ*, μ*, ϱ*, s3*, p_θ*,
  sign) (:data:`TG0`…+5), the body's kernel parameters (:data:`P0`…+8; per body, so a task may draw its
  body), the witness's parameters (:data:`W0`…+8), the step's reward, its named terms, distance, energy
  H, |s|², the running return and the last finished episode's return and final distance (``R_*``).
* ``K`` (:data:`K_ROWS`, N) int64: episode clock (steps), the body's seed and episodes drawn (the
  counter-based draws), the integrator's status and evaluations, the termination code
  (:data:`~flatbody_env.env.task.DOMAIN_CODES`, and :data:`CODE_LEFT_TOLERANCE`), terminated, truncated,
  an autoreset pending (NEXT_STEP), a host draw needed, and the statistics of an episode that ended in
  this step (``K_EP_*``).
* ``OBS``, ``FINAL`` (N, d) float32: observations, and the last observation of an episode that ended
  (SAME_STEP mode).
* ``A`` (N, n) the actions (float32 or float64).
* ``kcfg`` the task's kernel configuration (:meth:`~flatbody_env.env.task.ReachStationaryEllipse.kernel_config`:
  weights, tolerance, domain); ``scfg`` the episode sampler's (:data:`flatbody_env.env.sampling.CFG_SIZE`);
  ``xcfg`` (:data:`X_SIZE`) this module's: integrator, controls, episode length, autoreset mode, draws,
  task kind, reward, body ranges, witness settings; ``coeffs`` a splitting method's coefficients; the
  settling-rate table's nine arrays (:meth:`flatbody_env.env.targets.SettlingRateTable.kernel_arrays`).

Draws
-----
Counter-based (Philox-4x32-10: Salmon et al., SC'11, the generator of cuRAND and JAX), written as plain
integer arithmetic on uint64 holding 32-bit words, so every thread draws on its own and the CPU and a GPU
draw the same numbers. Uniform j of a body's episode e in stream s is a pure function of (the body's seed,
e, s, j) (:func:`uniform_at`): the key is the body's seed scrambled by one Philox call, the counter
(j // 2, e, s, 0). A body's seed is the batch's seed plus its index (Gymnasium's convention), so body i
of a batch reset with seed s draws what a single env reset with seed s + i draws, on every face and
device. The v0 ids keep their own draws (numpy generators, on the host): ``xcfg[X_DRAWS]`` = 0 marks
them, and the kernels then leave the draw to the caller (:data:`K_HOST`).

Rewards
-------
``xcfg[X_REWARD]`` = :data:`REWARD_TERMS` (the v0 ids): the sum of the task's named terms
(:mod:`flatbody_env.env.task`; ``alive`` and the failure on leaving for the hold task).
:data:`REWARD_TOLERANCE` (the v1 ids): a reward in [0, 1] per step on the task distance d alone, in
dm_control's ``tolerance`` form: ``success`` = (1 − β)·[d ≤ tol] and ``proximity`` = β·g(d) with
g = 1 within the tolerance and exp(−ln 10 · ((d − tol)/m)²) outside (0.1 at the margin m); 0 on a step
that ends the episode by failure. A step within the tolerance is worth at least 1/β times any step
outside, so return ranks like success (docs/tasks.md measures it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import float64, int64

from flatbody_env.env.kernels import post_step, post_step_lanes
from flatbody_env.env.sampling import (
    BALL_DRAWS,
    MAX_ATTEMPTS,
    START_BALL,
    START_NOISE,
    ball_state_kernel,
    candidate_kernel,
    initial_state_kernel,
)
from flatbody_env.env.targets import REJECT, UNSURE
from flatbody_env.env.task import (  # noqa: F401  (TOLERANCE_TERMS: the reward's names, read from here too)
    TASK_HOLD,
    TASK_REACH,
    TASK_WITNESS,
    TOLERANCE_TERMS,
    domain_code,
    omega12_kernel,
)
from flatbody_env.env.witness import square_wave, uncontrolled_offset
from flatbody_env.integrators.twopolar_kernels import env_step_into
from flatbody_env.physics.validation import MAX_EPISODE_STEPS

# --------------------------------------------------------------------------------------------- layout
Y0, TG0, P0, W0 = 0, 11, 17, 26
"""First rows of the state (11), the target (6), the body's kernel parameters (9) and the witness (9) in ``S``."""
R_REWARD, R_TERMS, R_DISTANCE, R_ENERGY, R_CASIMIR, R_RETURN, R_EP_RETURN, R_EP_DISTANCE = (
    35,
    36,
    43,
    44,
    45,
    46,
    47,
    48,
)
"""Rows of ``S``: the step's reward, its terms (up to :data:`MAX_TERMS`), distance, energy H, |s|², the current
episode's return so far, and the return and final distance of the episode that ended in the last step."""
MAX_TERMS = 7
S_ROWS = 49
P_CONSTANTS = (0, 2, 4, 6, 7)
"""The kernel parameters (rows ``P0 + i`` of ``S``) that are a drawn body's constants (J, J3, κ, a, b), in the order of
:data:`flatbody_env.env.any_body.BODY_OBSERVATION_NAMES`: the observation's entries 16–20 where the task observes the
body (:func:`reset_body` writes them)."""
K_CLOCK, K_SEED, K_EPISODE, K_STATUS, K_NFEV, K_CODE, K_TERMINATED, K_TRUNCATED = 0, 1, 2, 3, 4, 5, 6, 7
K_PENDING, K_HOST, K_EP_DONE, K_EP_LENGTH, K_EP_SUCCESS = 8, 9, 10, 11, 12
"""Rows of ``K``: ``K_PENDING`` an autoreset due at the next step (NEXT_STEP); ``K_HOST`` a reset whose draw the
host makes (the v0 ids); ``K_EP_*`` the length and success of the episode that ended in the last step."""
K_ROWS = 13
CODE_LEFT_TOLERANCE = 7
"""``K_CODE`` of a step that ends the episode because the body left the target's tolerance (the hold task);
0–6 are :data:`flatbody_env.env.task.DOMAIN_CODES`."""


def lanes(rows: int, n: int, dtype=np.float64) -> np.ndarray:
    """Zeros (``rows``, ``n``) in the lanes' layout (one row per quantity, one column per body) for the CPU loops: a
    view of a wider array whose rows lie an odd number of 64-byte cache lines apart. Rows a power-of-two multiple of
    4 KiB apart (``n`` = 512, 1024, 2048, ...) all fall into the same sets of a set-associative cache, and the per-body
    loops, which touch some twenty rows per body, then miss it at every body (measured: 0.84 µs against 0.66 µs per
    body-step at N = 1024 against 1030). Always a strided view (never C-contiguous), so the compiled loops have one
    layout whatever ``n``."""
    width = n + 1 + (-(n + 1)) % 8  # a whole number of cache lines, more than n
    if (width // 8) % 2 == 0:
        width += 8
    return np.zeros((rows, width), dtype)[:, :n]


X_DT, X_H, X_RTOL, X_ATOL, X_ETOL, X_KIND = 0, 1, 2, 3, 4, 5
X_LIMITS, X_MASK, X_NACT = 6, 10, 14
"""(τ1, τ2, τ3, f_ϱ) limits, which of them the action drives (0/1), and the action's size."""
X_MAX_STEPS, X_SAME_STEP, X_DRAWS = 15, 16, 17
X_TASK, X_REWARD, X_NTERMS, X_W_ALIVE, X_BETA, X_MARGIN = 18, 19, 20, 21, 22, 23
X_VARY_BODY, X_OBS_BODY, X_RANGES = 24, 25, 26
"""Whether the task draws its body per episode, appends the body's constants (J, J3, κ, a, b) to the
observation, and the ranges of those constants (10 entries: lo, hi each)."""
X_WIT = 36
"""Witness settings from here: steps, attempts, radius lo/hi (× tol), amplitude lo/hi, half-period lo/hi (steps),
start distance lo/hi, least uncontrolled offset (11 entries)."""
X_MAX_NFEV = 47
"""Each body's budget of right-hand-side evaluations per env step
(:data:`~flatbody_env.physics.validation.ENV_STEP_MAX_NFEV`;
DOP853 checks it before each of its steps)."""
X_OBS_TIME, X_TIME_UNIT = 48, 49
"""The observation's column of the episode's elapsed time (0: the task does not observe it) and the steps it counts
in (:attr:`~flatbody_env.env.task.ReachStationaryEllipse.observe_time`; :func:`observe_clock`)."""
X_SIZE = 50
REWARD_TERMS, REWARD_TOLERANCE = 0, 1

ERR_ACTION, ERR_NO_TARGET, ERR_START, ERR_NO_WITNESS = 1, 2, 3, 4
"""Error codes a launch flags (``FLAGS[0]``, the body in ``FLAGS[1]``): a non-finite action (that body was not
stepped), no target in :data:`~flatbody_env.env.sampling.MAX_ATTEMPTS` candidates, a start outside the domain, no
witnessed start in the allowed attempts."""
STREAM_EPISODE, STREAM_CLOCK = 0, 1
"""Philox streams (counter word 2): a reset's draws, the staggered clock."""
DRAWS_HOST, DRAWS_KERNEL = 0, 1
RESET_DRAW, RESET_START, RESET_OBSERVE = 0, 1, 2
"""What :func:`reset_body` draws: everything; the start only (the target given, e.g. ``options["target"]``);
nothing (state and target given, or drawn by the host)."""
_SCRAMBLE = (0xA4093822, 0x299F31D0)
"""The key of the one Philox call that turns a body's seed into its key."""


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


def seed_key(seed):
    """The Philox key (two 32-bit words) of a body's seed (an integer in [0, 2⁶³)): one Philox call on (seed, 0, 0)."""
    s = np.uint64(seed)
    x0, x1, x2, x3 = philox4x32(_SCRAMBLE[0], _SCRAMBLE[1], s & np.uint64(0xFFFFFFFF), s >> np.uint64(32), 0, 0)
    return x0, x1


def uniform_at(k0, k1, episode, stream, j):
    """Uniform number ``j`` in [0, 1) (53 random bits, numpy's construction from two words) of ``episode`` in
    ``stream`` under the body's key (k0, k1): words of Philox at counter (j // 2, episode, stream, 0)."""
    x0, x1, x2, x3 = philox4x32(k0, k1, j >> 1, episode, stream, 0)
    if j & 1:
        x0 = x2
        x1 = x3
    a = x0 >> np.uint64(5)
    b = x1 >> np.uint64(6)
    return (float(a) * 67108864.0 + float(b)) * (1.0 / 9007199254740992.0)


# --------------------------------------------------------------------------------------------- pieces
def proximity(d, tol, margin):
    """g(d) of the v1 reward (module docstring): 1 within the tolerance, a Gaussian of the excess, 0.1 at the margin."""
    if d <= tol:
        return 1.0
    x = (d - tol) / margin
    return math.exp(-2.302585092994046 * x * x)


def controls_body(A, b, xcfg, a, u):
    """Clip body ``b``'s action ``A[b]`` to [−1, 1] into ``a`` and scale the driven controls into ``u`` =
    (τ1, τ2, τ3, f_ϱ) (:func:`scale_controls`; the Python faces: :meth:`~flatbody_env.env.core.EnvConfig.controls`).
    False for a non-finite entry."""
    m = A.shape[1]
    for i in range(m):
        if not math.isfinite(A[b, i]):
            return False
    driven = 0
    for j in range(4):
        if xcfg[X_MASK + j] != 0.0:
            driven += 1
    for i in range(m):
        a[i] = min(1.0, max(-1.0, A[b, i])) if driven > 0 else 0.0
    scale_controls(xcfg, a, u)
    return True


def scale_controls(xcfg, a, u):
    """The driven controls ``u`` = (τ1, τ2, τ3, f_ϱ) of the clipped action ``a``: each driven one its entry of ``a``
    times its limit, the others 0."""
    c = 0
    for j in range(4):
        if xcfg[X_MASK + j] != 0.0:
            u[j] = a[c] * xcfg[X_LIMITS + j]
            c += 1
        else:
            u[j] = 0.0


def integrate_body(xcfg, coeffs, y, u, p, out, K13, ynew, ytmp, vel, force, f, counters):
    """One env step of the state ``y`` under the controls ``u`` into ``out`` by the configured method
    (:func:`~flatbody_env.integrators.twopolar_kernels.env_step_into`, at most
    :data:`~flatbody_env.physics.validation.ENV_STEP_MAX_NFEV` evaluations, ``counters[3]``); returns its status."""
    counters[0] = 0
    counters[1] = 0
    counters[2] = 0
    counters[3] = int(xcfg[X_MAX_NFEV])
    return env_step_into(
        int(xcfg[X_KIND]), coeffs, y, u, p, xcfg[X_DT], xcfg[X_H], xcfg[X_RTOL], xcfg[X_ATOL], xcfg[X_ETOL], out, K13,
        ynew, ytmp, vel, force, f, counters,
    )  # fmt: skip


def load_body(b, S, y, tg, p):
    """Body ``b``'s state, target and kernel parameters into the contiguous work arrays ``y`` (11,), ``tg`` (6,),
    ``p`` (9,)."""
    for i in range(11):
        y[i] = S[Y0 + i, b]
    for i in range(6):
        tg[i] = S[TG0 + i, b]
    for i in range(9):
        p[i] = S[P0 + i, b]


# --------------------------------------------------------------------------------------------- reset
def draw_body(
    b, S, K, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate, fine_margin,
    mode, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, terms,
):  # fmt: skip
    """Body ``b``'s next episode (v1 draws, module docstring): its body (a task that draws one), a target (``mode``
    :data:`RESET_DRAW`; else the target in ``S`` is kept) and a start, into ``S``; its episode count advances.
    Returns 0 or :data:`ERR_NO_TARGET` / :data:`ERR_NO_WITNESS` (the body's rows are then left as they were)."""
    k0, k1 = seed_key(K[K_SEED, b])
    e = K[K_EPISODE, b]
    K[K_EPISODE, b] = e + 1
    j = 0
    for i in range(9):
        p[i] = S[P0 + i, b]
    for i in range(16):
        sl[i] = scfg[i]
    if xcfg[X_VARY_BODY] != 0.0:  # J, J3, κ, a, b log-uniform in their ranges: V3 and V_ϱ (eqs. (39), (40))
        for c in range(5):
            lo = xcfg[X_RANGES + 2 * c]
            hi = xcfg[X_RANGES + 2 * c + 1]
            cand[c] = lo * (hi / lo) ** uniform_at(k0, k1, e, STREAM_EPISODE, j)
            j += 1
        p[0] = cand[0]
        p[1] = cand[0]
        p[2] = cand[1]
        p[3] = 3.0
        p[4] = cand[2]
        p[5] = 0.0
        p[6] = cand[3]
        p[7] = cand[4]
        p[8] = 1.0
        sl[8] = (cand[3] / cand[4]) ** (1.0 / 3.0)  # ϱ* of V_ϱ (eq. (54))
    if mode == RESET_DRAW:
        found = False
        for _ in range(MAX_ATTEMPTS):
            code = candidate_kernel(
                uniform_at(k0, k1, e, STREAM_EPISODE, j), uniform_at(k0, k1, e, STREAM_EPISODE, j + 1), uniform_at(k0,
                k1, e, STREAM_EPISODE, j + 2), sl, p, pot, table_code, grid, rate, margin, invalid, edge_lo, edge_hi,
                refined, fine_rate, fine_margin, cand,
            )  # fmt: skip
            j += 3
            if code in (REJECT, UNSURE):  # v1: a shape the table is unsure about is drawn again
                continue
            for i in range(5):
                tg[i] = cand[i]
            tg[5] = cand[9]
            found = True
            break
        if not found:
            return ERR_NO_TARGET
    else:
        for i in range(6):
            tg[i] = S[TG0 + i, b]
    task = xcfg[X_TASK]
    if task == TASK_WITNESS:
        if not witness_start(
            k0,
            k1,
            e,
            j,
            coeffs,
            kcfg,
            xcfg,
            tg,
            p,
            y,
            a,
            u,
            out,
            K13,
            ynew,
            ytmp,
            vel,
            force,
            f,
            counters,
            terms,
            uu,
            cand,
        ):
            return ERR_NO_WITNESS
        for i in range(9):
            S[W0 + i, b] = cand[i]
    else:
        start = sl[13]
        if start == START_BALL:
            for i in range(BALL_DRAWS):
                uu[i] = uniform_at(k0, k1, e, STREAM_EPISODE, j + i)
            ball_state_kernel(uu, sl[14], sl[15], tg[0], tg[1], tg[2], tg[3], tg[4], p[0], p[2], y)
        elif start == START_NOISE:
            torque = sl[7] != 0.0
            for i in range(10 if torque else 9):
                uu[i] = uniform_at(k0, k1, e, STREAM_EPISODE, j + i)
            initial_state_kernel(uu, sl[6], torque, tg[0], tg[1], tg[2], tg[3], tg[4], y)
    for i in range(11):
        S[Y0 + i, b] = y[i]
    for i in range(6):
        S[TG0 + i, b] = tg[i]
    for i in range(9):
        S[P0 + i, b] = p[i]
    return 0


def witness_start(
    k0, k1, e, j, coeffs, kcfg, xcfg, tg, p, y, a, u, out, K13, ynew, ytmp, vel, force, f, counters, terms, uu, wp
):
    """A start with a witness (:mod:`flatbody_env.env.witness`, "The draw", on this module's uniforms from number
    ``j`` of episode ``e``): a point y_b in the success ball, the reversed run from 𝓡(y_b) under square waves, the
    start 𝓡(z(T)) kept when the run stayed in the domain, its distance lies in the start range and its offset in the
    uncontrolled coordinates is large enough. The start into ``y``, the witness's parameters (amplitude, then
    half-period and phase per driven control) into ``wp`` (9,); False when the attempts run out."""
    tol = kcfg[6]
    n_act = int(xcfg[X_NACT])
    steps = int(xcfg[X_WIT])
    h_lo = int(xcfg[X_WIT + 6])
    h_hi = int(xcfg[X_WIT + 7])
    no_dil = 1.0 if xcfg[X_MASK + 3] == 0.0 else 0.0
    no_tau = 1.0 if xcfg[X_MASK + 2] == 0.0 else 0.0
    for _ in range(int(xcfg[X_WIT + 1])):
        for i in range(BALL_DRAWS):
            uu[i] = uniform_at(k0, k1, e, STREAM_EPISODE, j + i)
        j += BALL_DRAWS
        ball_state_kernel(
            uu, xcfg[X_WIT + 2] * tol, xcfg[X_WIT + 3] * tol, tg[0], tg[1], tg[2], tg[3], tg[4], p[0], p[2], ynew
        )
        amp = xcfg[X_WIT + 4] + (xcfg[X_WIT + 5] - xcfg[X_WIT + 4]) * uniform_at(k0, k1, e, STREAM_EPISODE, j)
        j += 1
        for i in range(9):
            wp[i] = 0.0
        wp[0] = amp
        for c in range(n_act):
            half = h_lo + min(int((h_hi - h_lo + 1) * uniform_at(k0, k1, e, STREAM_EPISODE, j)), h_hi - h_lo)
            phase = min(int(2 * half * uniform_at(k0, k1, e, STREAM_EPISODE, j + 1)), 2 * half - 1)
            wp[1 + 2 * c] = half
            wp[2 + 2 * c] = phase
            j += 2
        for i in range(11):  # 𝓡(y_b): the momenta s1 … p_ϱ negated
            y[i] = -ynew[i] if i < 7 else ynew[i]
        ok = True
        for k in range(steps):
            for c in range(n_act):
                a[c] = min(1.0, max(-1.0, square_wave(k, amp, int(wp[1 + 2 * c]), int(wp[2 + 2 * c]))))
            scale_controls(xcfg, a, u)
            status = integrate_body(xcfg, coeffs, y, u, p, out, K13, ynew, ytmp, vel, force, f, counters)
            if status != 0 or domain_code(out, kcfg) != 0:
                ok = False
                break
            for i in range(11):
                y[i] = out[i]
        if not ok:
            continue
        for i in range(7):  # the start 𝓡(z(T))
            y[i] = -y[i]
        w1, w2 = omega12_kernel(y, p[0], p[2])
        dl = y[7] - tg[0]
        dm = y[8] - tg[1]
        dr = y[9] - tg[2]
        ds = y[2] - tg[3]
        d0 = math.sqrt(
            dl * dl + dm * dm + dr * dr + ds * ds + w1 * w1 + w2 * w2 + y[4] * y[4] + y[5] * y[5] + y[6] * y[6]
        )
        off = uncontrolled_offset(y, tg, p[0], p[2], no_dil, no_tau)
        if xcfg[X_WIT + 8] <= d0 <= xcfg[X_WIT + 9] and off >= xcfg[X_WIT + 10]:
            return True
    return False


MAX_OBSERVED_STEPS = MAX_EPISODE_STEPS
"""The observed time stops here (the longest episode a vector env allows; an unlimited single env counts on), so it
stays within the observation space."""


def observe_clock(b, K, OBS, xcfg):
    """Where the task observes time (:data:`X_OBS_TIME`): body ``b``'s elapsed steps, its clock over
    :data:`X_TIME_UNIT` (0 at a reset, 1 at the v1 ids' truncation), into its observation ``OBS[b]``."""
    col = int(xcfg[X_OBS_TIME])
    if col != 0:
        OBS[b, col] = min(K[K_CLOCK, b], MAX_OBSERVED_STEPS) / xcfg[X_TIME_UNIT]


def reset_body(
    b, mode, write_info, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
    fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f,
    counters, yout, terms, sc,
):  # fmt: skip
    """Reset body ``b``: its draws (:func:`draw_body` with ``mode`` :data:`RESET_DRAW` or :data:`RESET_START`; with
    :data:`RESET_OBSERVE` the state, target and body in ``S`` are kept), then its observation into ``OBS[b]``
    (:func:`~flatbody_env.env.kernels.post_step` of the start; the body's constants appended where the task
    observes them), its clock and running return cleared; with ``write_info`` also its step rows (a zero reward and
    terms, not ended, its distance, energy and |s|²) — an autoreset within the step that ended the episode
    (SAME_STEP) keeps that step's. Returns 0, an error of :func:`draw_body`, or :data:`ERR_START` (the start lies
    outside the domain)."""
    if mode != RESET_OBSERVE and xcfg[X_DRAWS] == DRAWS_KERNEL:
        err = draw_body(
            b, S, K, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate,
            fine_margin, mode, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f,
            counters, terms,
        )  # fmt: skip
        if err != 0:
            return err
    load_body(b, S, y, tg, p)
    post_step(y, y, 0, a, 0, tg, kcfg, p, yout, OBS[b], terms, sc, vel, force)
    if xcfg[X_OBS_BODY] != 0.0:
        OBS[b, 16] = p[0]
        OBS[b, 17] = p[2]
        OBS[b, 18] = p[4]
        OBS[b, 19] = p[6]
        OBS[b, 20] = p[7]
    if write_info != 0:
        S[R_EP_RETURN, b] = 0.0
        S[R_EP_DISTANCE, b] = 0.0
        K[K_EP_LENGTH, b] = 0
        K[K_EP_SUCCESS, b] = 0
        S[R_REWARD, b] = 0.0
        for i in range(MAX_TERMS):
            S[R_TERMS + i, b] = 0.0
        S[R_DISTANCE, b] = sc[0]
        S[R_ENERGY, b] = sc[1]
        S[R_CASIMIR, b] = sc[2]
        K[K_STATUS, b] = 0
        K[K_NFEV, b] = 0
        K[K_CODE, b] = int(sc[3])
        K[K_TERMINATED, b] = 0
        K[K_TRUNCATED, b] = 0
    S[R_RETURN, b] = 0.0
    K[K_CLOCK, b] = 0
    K[K_PENDING, b] = 0
    K[K_HOST, b] = 0
    observe_clock(b, K, OBS, xcfg)
    return ERR_START if sc[3] != 0.0 else 0


def stagger_body(b, K, max_steps):
    """Body ``b``'s clock at a uniform step in [0, ``max_steps``) (stream :data:`STREAM_CLOCK` of its current
    episode)."""
    k0, k1 = seed_key(K[K_SEED, b])
    u = uniform_at(k0, k1, K[K_EPISODE, b], STREAM_CLOCK, 0)
    K[K_CLOCK, b] = min(int(u * max_steps), max_steps - 1)


# --------------------------------------------------------------------------------------------- step
def close_step(b, ended, status, nfev, S, K, kcfg, xcfg, yout, terms, sc):
    """The task's part of body ``b``'s step after :func:`~flatbody_env.env.kernels.post_step` (``ended``, the kept state
    ``yout``, the v0 terms ``terms``, the scalars ``sc`` = distance, energy, |s|², domain code): the task's own
    termination (the hold task ends outside the tolerance), the reward (module docstring), the clock, truncation and
    the episode's statistics, written into ``S`` and ``K``. Returns 1 when the episode ended in this step, else 0."""
    code = int(sc[3])
    tol = kcfg[6]
    leaves = 0
    if xcfg[X_TASK] == TASK_HOLD and ended == 0 and sc[0] > tol:
        leaves = 1
        code = CODE_LEFT_TOLERANCE
    if xcfg[X_REWARD] == REWARD_TERMS:
        if xcfg[X_TASK] == TASK_HOLD:  # the hold task's own terms: the failure on leaving, alive
            if leaves != 0:
                terms[5] = -kcfg[5]
            terms[6] = 0.0 if (ended != 0 or leaves != 0) else xcfg[X_W_ALIVE]
        n_terms = int(xcfg[X_NTERMS])
    else:
        beta = xcfg[X_BETA]
        alive = ended == 0 and leaves == 0
        terms[0] = (1.0 - beta) if (alive and sc[0] <= tol) else 0.0
        terms[1] = beta * proximity(sc[0], tol, xcfg[X_MARGIN]) if alive else 0.0
        n_terms = 2
    reward = 0.0
    for i in range(n_terms):
        reward += terms[i]
        S[R_TERMS + i, b] = terms[i]
    for i in range(11):
        S[Y0 + i, b] = yout[i]
    S[R_REWARD, b] = reward
    S[R_DISTANCE, b] = sc[0]
    S[R_ENERGY, b] = sc[1]
    S[R_CASIMIR, b] = sc[2]
    K[K_STATUS, b] = status
    K[K_NFEV, b] = nfev
    K[K_CODE, b] = code
    clock = K[K_CLOCK, b] + 1
    K[K_CLOCK, b] = clock
    terminated = 1 if (ended != 0 or leaves != 0) else 0
    truncated = 1 if (terminated == 0 and clock >= int(xcfg[X_MAX_STEPS])) else 0
    K[K_TERMINATED, b] = terminated
    K[K_TRUNCATED, b] = truncated
    total = S[R_RETURN, b] + reward
    S[R_RETURN, b] = total
    if terminated == 0 and truncated == 0:
        K[K_EP_DONE, b] = 0
        return 0
    K[K_EP_DONE, b] = 1
    K[K_EP_LENGTH, b] = clock
    K[K_EP_SUCCESS, b] = 1 if (terminated == 0 and sc[0] <= tol) else 0
    S[R_EP_RETURN, b] = total
    S[R_EP_DISTANCE, b] = sc[0]
    return 1


def end_episode(
    b, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate,
    fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout,
    terms, sc,
):  # fmt: skip
    """The autoreset of body ``b`` whose episode ended in this step: SAME_STEP keeps its last observation in
    ``FINAL[b]`` and resets it now (or marks a host draw, :data:`K_HOST`); NEXT_STEP marks it :data:`K_PENDING`.
    Returns 0 or a reset's error."""
    if xcfg[X_SAME_STEP] == 2.0:  # no autoreset (the single env: the user resets)
        return 0
    if xcfg[X_SAME_STEP] == 0.0:
        K[K_PENDING, b] = 1
        return 0
    for i in range(OBS.shape[1]):
        FINAL[b, i] = OBS[b, i]
    if xcfg[X_DRAWS] != DRAWS_KERNEL:
        K[K_HOST, b] = 1
        return 0
    return reset_body(
        b, RESET_DRAW, 0, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
        fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f,
        counters, yout, terms, sc,
    )  # fmt: skip


def pending_reset(
    b, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate,
    fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout,
    terms, sc,
):  # fmt: skip
    """NEXT_STEP: the step after an episode's end resets body ``b`` (its action is ignored; reward 0, not ended).
    The v1 draws run here; the v0 ids' host has drawn before the launch. Returns 0 or a reset's error."""
    K[K_EP_DONE, b] = 0
    mode = RESET_DRAW if xcfg[X_DRAWS] == DRAWS_KERNEL else RESET_OBSERVE
    return reset_body(
        b, mode, 1, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
        fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f,
        counters, yout, terms, sc,
    )  # fmt: skip


STEP_ENDED = -1
""":func:`advance_body`'s return when the body's episode ended in the step (its autoreset, :func:`end_episode`, is due)."""


def advance_body(b, A, S, K, OBS, coeffs, kcfg, xcfg, y, tg, p, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout,
                 terms, sc):  # fmt: skip
    """Body ``b``'s step without a reset: its action clipped and scaled (:func:`controls_body`), the integrator
    (:func:`integrate_body`), then :func:`~flatbody_env.env.kernels.post_step` (domain, kept state, observation,
    distance, energy) and :func:`close_step`. Returns 0, :data:`STEP_ENDED` when the episode ended, or
    :data:`ERR_ACTION` (the body is left untouched)."""
    if not controls_body(A, b, xcfg, a, u):
        return ERR_ACTION
    load_body(b, S, y, tg, p)
    status = integrate_body(xcfg, coeffs, y, u, p, out, K13, ynew, ytmp, vel, force, f, counters)
    ended = post_step(y, out, status, a, int(xcfg[X_NACT]), tg, kcfg, p, yout, OBS[b], terms, sc, vel, force)
    done = close_step(b, ended, status, counters[0], S, K, kcfg, xcfg, yout, terms, sc)
    observe_clock(b, K, OBS, xcfg)
    return STEP_ENDED if done != 0 else 0


def step_body(
    b, A, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate,
    fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout,
    terms, sc,
):  # fmt: skip
    """Body ``b``'s environment step: a pending reset (NEXT_STEP, :func:`pending_reset`), or :func:`advance_body` and,
    when the episode ended, :func:`end_episode`. Work arrays: ``y``, ``out``, ``ynew``, ``ytmp``, ``f``, ``yout``
    (11,), ``tg`` (6,), ``p``, ``wp`` (9,), ``sl`` (16,), ``pot`` (7, 4), ``table_code`` (1,) int64, ``cand`` (10,),
    ``uu`` (12,), ``a``, ``u`` (4,), ``K13`` (13, 11), ``vel`` (7,), ``force`` (4,), ``counters`` (4,) int64,
    ``terms`` (7,), ``sc`` (4,). Returns 0 or an error code (:data:`ERR_ACTION`: the body is left untouched). The CUDA
    kernel calls it per body; the CPU loop (:func:`step_lanes`) composes the same three calls itself."""
    if K[K_PENDING, b] != 0:
        return pending_reset(
            b, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined, fine_rate,
            fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters,
            yout, terms, sc,
        )  # fmt: skip
    err = advance_body(
        b, A, S, K, OBS, coeffs, kcfg, xcfg, y, tg, p, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms,
        sc,
    )  # fmt: skip
    if err != STEP_ENDED:
        return err
    return end_episode(
        b, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
        fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f,
        counters, yout, terms, sc,
    )  # fmt: skip


# --------------------------------------------------------------------------------------------- CPU loops
KC0 = X_SIZE
"""``CFG`` (the CPU loops' one configuration vector): ``xcfg`` at 0, ``kcfg`` at :data:`KC0`, ``scfg`` at :data:`SC0`,
a splitting method's coefficients at :data:`CO0` (:func:`pack_config`)."""
SC0 = KC0 + 14
CO0 = SC0 + 16
WF_SIZE = 11 + 6 + 9 + 16 + 28 + 10 + 12 + 4 + 4 + 11 + 143 + 11 + 11 + 7 + 4 + 11 + 11 + MAX_TERMS + 4
"""Floats of one body's work arrays (:func:`work_views`)."""
WI_SIZE = 5


def pack_config(xcfg, kcfg, scfg, coeffs) -> np.ndarray:
    """The CPU loops' ``CFG``: ``xcfg``, ``kcfg``, ``scfg`` and ``coeffs`` end to end (:data:`KC0`)."""
    return np.concatenate([xcfg, kcfg, scfg, coeffs]).astype(np.float64)


WF_FLAT = WF_SIZE - 28 - 143
"""Floats of one body's one-dimensional work arrays (:func:`flat_views`); the two 2-D ones follow them in ``WF``."""


def flat_views(WF, WI):
    """The one-dimensional work arrays of one body's step or reset (:func:`step_body`'s docstring) as views of the flat
    ``WF`` (at least :data:`WF_FLAT` floats) and ``WI`` (:data:`WI_SIZE` int64): ``y``, ``tg``, ``p``, ``sl``,
    ``table_code``, ``cand``, ``uu``, ``a``, ``u``, ``out``, ``ynew``, ``ytmp``, ``vel``, ``force``, ``f``,
    ``counters``, ``yout``, ``terms``, ``sc``."""
    o = 0
    y = WF[o : o + 11]
    o += 11
    tg = WF[o : o + 6]
    o += 6
    p = WF[o : o + 9]
    o += 9
    sl = WF[o : o + 16]
    o += 16
    cand = WF[o : o + 10]
    o += 10
    uu = WF[o : o + 12]
    o += 12
    a = WF[o : o + 4]
    o += 4
    u = WF[o : o + 4]
    o += 4
    out = WF[o : o + 11]
    o += 11
    ynew = WF[o : o + 11]
    o += 11
    ytmp = WF[o : o + 11]
    o += 11
    vel = WF[o : o + 7]
    o += 7
    force = WF[o : o + 4]
    o += 4
    f = WF[o : o + 11]
    o += 11
    yout = WF[o : o + 11]
    o += 11
    terms = WF[o : o + MAX_TERMS]
    o += MAX_TERMS
    sc = WF[o : o + 4]
    counters = WI[0:4]
    table_code = WI[4:5]
    return y, tg, p, sl, table_code, cand, uu, a, u, out, ynew, ytmp, vel, force, f, counters, yout, terms, sc


def work_views(WF, WI):
    """Every work array of one body's step or reset, in :func:`step_body`'s order, as views of the flat ``WF``
    (:data:`WF_SIZE` floats: :func:`flat_views`, then ``pot`` (7, 4) and ``K13`` (13, 11)) and ``WI``, allocated once
    by the caller (the CPU loops)."""
    y, tg, p, sl, table_code, cand, uu, a, u, out, ynew, ytmp, vel, force, f, counters, yout, terms, sc = flat_views(
        WF, WI
    )
    pot = WF[WF_FLAT : WF_FLAT + 28].reshape((7, 4))
    K13 = WF[WF_FLAT + 28 : WF_FLAT + 171].reshape((13, 11))
    return y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc


def _table():
    """The shipped settling-rate table's arrays (:meth:`flatbody_env.env.targets.SettlingRateTable.kernel_arrays`):
    constants of the CPU loops (the only table the v1 draws read; zeros of the right types without the file)."""
    from flatbody_env.env.targets import EMPTY_KERNEL_ARRAYS, shipped_table

    table = shipped_table()
    return table.kernel_arrays() if table is not None else EMPTY_KERNEL_ARRAYS


TABLE = _table()
_GRID, _RATE, _MARGIN, _INVALID, _EDGE_LO, _EDGE_HI, _REFINED, _FINE_RATE, _FINE_MARGIN = TABLE


def step_lanes(A, S, K, OBS, FINAL, FLAGS, CFG, WF, WI):
    """:func:`step_body` for every body, one after another (the CPU side of the CUDA step kernel: its three calls made
    here, the same arithmetic, bit for bit); ``CFG`` from :func:`pack_config`, ``WF``/``WI`` the work
    (:func:`work_views`)."""
    y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc = (
        work_views(WF, WI)
    )
    xcfg = CFG[:KC0]
    kcfg = CFG[KC0:SC0]
    scfg = CFG[SC0:CO0]
    coeffs = CFG[CO0:]
    for b in range(S.shape[1]):
        # step_body's three calls, written out: a compiled call with its 40 arrays costs ≈ 0.9 µs of reference counts
        # per body (CPython hands a call of more than 30 arguments over as a tuple, which numba does not inline)
        if K[K_PENDING, b] != 0:
            err = pending_reset(
                b, S, K, OBS, coeffs, kcfg, scfg, xcfg, _GRID, _RATE, _MARGIN, _INVALID, _EDGE_LO, _EDGE_HI, _REFINED,
                _FINE_RATE, _FINE_MARGIN, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel,
                force, f, counters, yout, terms, sc,
            )  # fmt: skip
        else:
            err = advance_body(
                b, A, S, K, OBS, coeffs, kcfg, xcfg, y, tg, p, a, u, out, K13, ynew, ytmp, vel, force, f, counters,
                yout, terms, sc,
            )  # fmt: skip
            if err == STEP_ENDED:
                err = end_episode(
                    b, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, _GRID, _RATE, _MARGIN, _INVALID, _EDGE_LO, _EDGE_HI,
                    _REFINED, _FINE_RATE, _FINE_MARGIN, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew,
                    ytmp, vel, force, f, counters, yout, terms, sc,
                )  # fmt: skip
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def controls_lanes(A, S, K, xcfg, AC, U):
    """:func:`controls_body` for every body (the clipped actions into ``AC`` (N, n), the controls into ``U`` (4, N)),
    before a batched integrator step (:func:`finish_lanes`); a body with a pending reset gets zero controls. The
    caller has checked that the actions are finite."""
    a = np.zeros(4)
    u = np.empty(4)
    for b in range(S.shape[1]):
        if K[K_PENDING, b] != 0 or not controls_body(A, b, xcfg, a, u):
            for j in range(4):
                U[j, b] = 0.0
            continue
        for i in range(AC.shape[1]):
            AC[b, i] = a[i]
        for j in range(4):
            U[j, b] = u[j]


def finish_lanes(AC, OUT, STATUS, NFEV, S, K, OBS, FINAL, FLAGS, CFG, WF, WI, LW):
    """The rest of :func:`step_body` for every body after a batched integrator step (``OUT`` (11, N), ``STATUS``,
    ``NFEV``): the bookkeeping of all bodies at once by :func:`~flatbody_env.env.kernels.post_step_lanes` (the
    structure-of-arrays twin of :func:`~flatbody_env.env.kernels.post_step`, bit for bit, each body with its own
    parameters),
    then per body a pending reset or :func:`close_step` and :func:`end_episode`. With :func:`controls_lanes` and a
    batched integrator it computes what :func:`step_lanes` computes, bit for bit. ``LW``: the lanes' work arrays
    (:func:`lane_work`)."""
    y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc = (
        work_views(WF, WI)
    )
    xcfg = CFG[:KC0]
    kcfg = CFG[KC0:SC0]
    scfg = CFG[SC0:CO0]
    coeffs = CFG[CO0:]
    YOUT, TERMS, SC, ENDED, ACT2, Tt, TG4, yk = LW
    n = S.shape[1]
    timed = xcfg[X_OBS_TIME] != 0.0  # read once: the per-body loop below is the batch's hot path
    for b in range(n):
        for i in range(4):
            TG4[b, i] = S[TG0 + i, b]
    post_step_lanes(
        S[Y0 : Y0 + 11],
        OUT,
        STATUS,
        AC,
        int(xcfg[X_NACT]),
        TG4,
        kcfg,
        S[P0 : P0 + 9],
        YOUT,
        OBS,
        TERMS,
        SC,
        ENDED,
        ACT2,
        Tt,
        vel,
        force,
        yk,
    )
    for b in range(n):
        if K[K_PENDING, b] != 0:
            err = pending_reset(
                b, S, K, OBS, coeffs, kcfg, scfg, xcfg, _GRID, _RATE, _MARGIN, _INVALID, _EDGE_LO, _EDGE_HI, _REFINED,
                _FINE_RATE, _FINE_MARGIN, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel,
                force, f, counters, yout, terms, sc,
            )  # fmt: skip
        else:
            for i in range(11):
                yout[i] = YOUT[i, b]
            for i in range(6):
                terms[i] = TERMS[i, b]
            for i in range(4):
                sc[i] = SC[i, b]
            err = 0
            done = close_step(b, ENDED[b], STATUS[b], NFEV[b], S, K, kcfg, xcfg, yout, terms, sc)
            if timed:
                observe_clock(b, K, OBS, xcfg)
            if done != 0:
                err = end_episode(
                    b, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, _GRID, _RATE, _MARGIN, _INVALID, _EDGE_LO, _EDGE_HI,
                    _REFINED, _FINE_RATE, _FINE_MARGIN, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew,
                    ytmp, vel, force, f, counters, yout, terms, sc,
                )  # fmt: skip
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def lane_work(n: int) -> tuple:
    """The work arrays of :func:`finish_lanes` for ``n`` bodies (:func:`lanes`)."""
    return (
        lanes(11, n), lanes(6, n), lanes(4, n), np.zeros(n, np.int64), np.zeros(n), lanes(4, n), np.zeros((n, 4)),
        np.zeros(11),
    )  # fmt: skip


def reset_slot(
    b, mode, write_info, stagger, S, K, OBS, FINAL, FLAGS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid,
    edge_lo, edge_hi, refined, fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew,
    ytmp, vel, force, f, counters, yout, terms, sc,
):  # fmt: skip
    """An explicit reset of body ``b`` (``reset()``, not an autoreset): :func:`reset_body`, its last episode's
    statistics and final observation cleared (with ``write_info``), its clock staggered (``stagger``), an error into
    ``FLAGS``."""
    err = reset_body(
        b, mode, write_info, S, K, OBS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi,
        refined, fine_rate, fine_margin, y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel,
        force, f, counters, yout, terms, sc,
    )  # fmt: skip
    if write_info != 0:
        K[K_EP_DONE, b] = 0
        for i in range(FINAL.shape[1]):
            FINAL[b, i] = 0.0
    if stagger != 0:
        stagger_body(b, K, int(xcfg[X_MAX_STEPS]))
        observe_clock(b, K, OBS, xcfg)
    if err != 0:
        FLAGS[0] = err
        FLAGS[1] = b


def reset_lanes(MASK, mode, write_info, stagger, S, K, OBS, FINAL, FLAGS, CFG, WF, WI):
    """:func:`reset_slot` for the bodies with ``MASK[b]`` set."""
    y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc = (
        work_views(WF, WI)
    )
    xcfg = CFG[:KC0]
    kcfg = CFG[KC0:SC0]
    scfg = CFG[SC0:CO0]
    coeffs = CFG[CO0:]
    for b in range(S.shape[1]):
        if MASK[b] != 0:
            reset_slot(
                b, mode, write_info, stagger, S, K, OBS, FINAL, FLAGS, coeffs, kcfg, scfg, xcfg, _GRID, _RATE, _MARGIN,
                _INVALID, _EDGE_LO, _EDGE_HI, _REFINED, _FINE_RATE, _FINE_MARGIN, y, tg, p, sl, pot, table_code, cand,
                uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc,
            )  # fmt: skip


# --------------------------------------------------------------------------------------------- CUDA kernels
cuda = None
"""numba.cuda in the kernels' globals (bound by :func:`flatbody_env.integrators.cuda.kernel` when it compiles them)."""


def _cuda_work(WF, WI, pot, K13):
    """The work arrays of one thread in :func:`step_body`'s order: :func:`flat_views` of ``WF`` (:data:`WF_FLAT`
    float64) and ``WI`` (:data:`WI_SIZE` int64), and ``pot`` (7, 4), ``K13`` (13, 11) — the kernel's own local arrays,
    zeroed as the CPU loops' are when first allocated.

    The kernel allocates them itself (``cuda.local.array`` in its own body): a local array lives as long as the function
    that allocates it, so a helper that allocated and returned them would hand out memory whose lifetime ended — on a GPU
    the compiler may then place other arrays over it (numba's simulator, which makes local arrays numpy arrays, cannot
    show that). The 2-D arrays are allocated 2-D rather than reshaped from ``WF``: numba-cuda reshapes by linking a
    CUDA source of its own, and a kernel that links one cannot be cached on disk."""
    for i in range(WF.size):
        WF[i] = 0.0
    for i in range(WI.size):
        WI[i] = 0
    for i in range(7):
        for j in range(4):
            pot[i, j] = 0.0
    for i in range(13):
        for j in range(11):
            K13[i, j] = 0.0
    y, tg, p, sl, table_code, cand, uu, a, u, out, ynew, ytmp, vel, force, f, counters, yout, terms, sc = flat_views(
        WF, WI
    )
    return y, tg, p, sl, pot, table_code, cand, uu, a, u, out, K13, ynew, ytmp, vel, force, f, counters, yout, terms, sc


def _step_kernel(
    A, S, K, OBS, FINAL, FLAGS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
    fine_rate, fine_margin,
):  # fmt: skip
    """One thread per body: :func:`step_body` with local work arrays (the CUDA side of :func:`step_lanes`)."""
    b = cuda.grid(1)
    if b < S.shape[1]:
        work = _cuda_work(
            cuda.local.array(WF_FLAT, float64),
            cuda.local.array(WI_SIZE, int64),
            cuda.local.array((7, 4), float64),
            cuda.local.array((13, 11), float64),
        )
        err = step_body(
            b, A, S, K, OBS, FINAL, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid, edge_lo, edge_hi, refined,
            fine_rate, fine_margin, *work,
        )  # fmt: skip
        if err != 0:
            FLAGS[0] = err
            FLAGS[1] = b


def _reset_kernel(
    MASK, mode, write_info, stagger, S, K, OBS, FINAL, FLAGS, coeffs, kcfg, scfg, xcfg, grid, rate, margin, invalid,
    edge_lo, edge_hi, refined, fine_rate, fine_margin,
):  # fmt: skip
    """One thread per body: :func:`reset_body` where ``MASK[b]`` is set (the CUDA side of :func:`reset_lanes`)."""
    b = cuda.grid(1)
    if b < S.shape[1] and MASK[b] != 0:
        work = _cuda_work(
            cuda.local.array(WF_FLAT, float64),
            cuda.local.array(WI_SIZE, int64),
            cuda.local.array((7, 4), float64),
            cuda.local.array((13, 11), float64),
        )
        reset_slot(
            b, mode, write_info, stagger, S, K, OBS, FINAL, FLAGS, coeffs, kcfg, scfg, xcfg, grid, rate, margin,
            invalid, edge_lo, edge_hi, refined, fine_rate, fine_margin, *work,
        )  # fmt: skip


_CPU: dict = {}


def cpu(name: str):
    """The compiled CPU loop ``name`` (:func:`step_lanes`, :func:`controls_lanes`, :func:`finish_lanes`,
    :func:`reset_lanes`), compiled on first use (:func:`~flatbody_env.integrators.jit.retarget`)."""
    fn = _CPU.get(name)
    if fn is None:
        from flatbody_env.integrators.jit import retarget

        fn = _CPU[name] = retarget(globals()[name])
    return fn


def cuda_kernels() -> tuple:
    """The CUDA step and reset kernels (compiled once per process by :func:`flatbody_env.integrators.cuda.kernel`)."""
    from flatbody_env.integrators import cuda as _cuda

    return tuple(_cuda.kernel(k) for k in (_step_kernel, _reset_kernel))


__all__ = [
    "CODE_LEFT_TOLERANCE",
    "DRAWS_HOST",
    "DRAWS_KERNEL",
    "ERR_ACTION",
    "ERR_NO_TARGET",
    "ERR_NO_WITNESS",
    "ERR_START",
    "K_ROWS",
    "REWARD_TERMS",
    "REWARD_TOLERANCE",
    "S_ROWS",
    "TASK_HOLD",
    "TASK_REACH",
    "TASK_WITNESS",
    "TOLERANCE_TERMS",
    "X_SIZE",
    "controls_body",
    "cpu",
    "cuda_kernels",
    "draw_body",
    "lanes",
    "philox4x32",
    "proximity",
    "reset_body",
    "seed_key",
    "step_body",
    "uniform_at",
]
