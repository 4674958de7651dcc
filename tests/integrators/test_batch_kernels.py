"""The fused structure-of-arrays DOP853 env step equals the scalar kernel lane by lane, bit for bit,
including lanes it must hand back (rejected steps, chart failures)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import random_lanes

from flatbody_env.integrators import batch_kernels
from flatbody_env.integrators.batch_kernels import DOP853Batch
from flatbody_env.integrators.compiled_methods import env_stepper, kernel_params
from flatbody_env.physics.body import default_body


def _lanes(n, seed):
    Y, U = random_lanes(n, seed)
    # hard lanes: a fast approach to lambda = mu (rejections / chart singularity) and huge momenta
    Y[7, 0], Y[8, 0], Y[4, 0], Y[5, 0] = 1.001, 0.999, -3.0, 3.0
    Y[4, 1] = 40.0
    return np.ascontiguousarray(Y), np.ascontiguousarray(U)


@pytest.mark.parametrize("n", [37, 2 * batch_kernels.BLOCK + 5])
def test_fused_batch_equals_scalar_kernel_bitwise(n):
    P = kernel_params(default_body())
    Y, U = _lanes(n, 0)
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    DOP853Batch(n)(Y, U, P, 0.05, 1e-11, 1e-11, np.inf, OUT, S, NF)
    st = env_stepper("DOP853-numba")
    handed_back = 0
    for k in range(n):
        out = np.empty(11)
        counters = np.zeros(3, np.int64)
        status = st.step_counted(Y[:, k].copy(), U[:, k].copy(), P, 0.05, 0.05, 1e-11, 1e-11, np.inf, out, counters)
        assert S[k] == status and NF[k] == counters[0]
        np.testing.assert_array_equal(OUT[:, k], out)
        handed_back += counters[0] != 13
    assert handed_back >= 1  # the hard lanes were redone with several steps
    assert NF.min() == 13


def _check_lanes_against_scalar(Y, U, P, tol=1e-11):
    n = Y.shape[1]
    OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
    DOP853Batch(n)(Y, U, P, 0.05, tol, tol, np.inf, OUT, S, NF)
    st = env_stepper("DOP853-numba")
    for k in range(n):
        out = np.empty(11)
        counters = np.zeros(3, np.int64)
        status = st.step_counted(Y[:, k].copy(), U[:, k].copy(), P, 0.05, 0.05, tol, tol, np.inf, out, counters)
        assert S[k] == status and NF[k] == counters[0], k
        np.testing.assert_array_equal(OUT[:, k], out)
    return S, NF


def test_many_rejected_lanes_follow_the_scalar_step_control_bitwise():
    """Lanes whose single step is rejected are redone together (fused, each with its own step sizes):
    every lane's state, status and function count are the scalar kernel's — also for a lane whose
    step collapses (non-finite state), and across more than one block."""
    P = kernel_params(default_body())
    n = 3 * batch_kernels.BLOCK + 9
    Y, U = _lanes(n, 5)
    rng = np.random.default_rng(6)
    Y[4:7, 2:] *= rng.uniform(5, 40, (3, n - 2))  # fast shape motion: most single steps are rejected
    Y[0:2, 2:] *= 20.0
    Y[0, 7] = np.nan  # the step collapses: handed to the scalar kernel
    Y[7, 9], Y[8, 9], Y[4, 9], Y[5, 9] = 1.01, 0.99, -30.0, 30.0  # thrown at λ = μ (the σ₋ barrier turns it back)
    S, NF = _check_lanes_against_scalar(np.ascontiguousarray(Y), U, P)
    assert (NF > 13).sum() > batch_kernels.BLOCK  # more than one block of lanes took several steps
    assert S[7] != 0
    assert np.unique(NF).size > 3  # lanes needed different numbers of attempts


def test_a_batch_of_bodies_steps_fused_each_lane_with_its_own_body_bitwise():
    """Each lane's own body (J1 = J2, J3, V3's κ, the thickness constants: a body drawn per episode), given as P
    (9, N): every lane's state, status and count are the scalar kernel's for that body — redone lanes, lanes handed
    to the scalar kernel (a collapse, the energy check) and more than one block included; the same parameters in
    every column step as the one body given once."""
    from flatbody_env.physics.body import Body, Inertia
    from flatbody_env.physics.potentials import V3, ThicknessPotential

    rng = np.random.default_rng(11)
    n = 2 * batch_kernels.BLOCK + 7
    Y, U = _lanes(n, 12)
    Y[4:7, 3:40] *= 20.0  # fast shape motion: rejected single steps, redone fused
    Y[0, 5] = np.nan  # collapses: the scalar kernel
    bodies = [
        Body(inertia=Inertia.isotropic(J, J3), potential=V3(kappa=kappa), thickness=ThicknessPotential(a=a, b=b))
        for J, J3, kappa, a, b in 0.5 * 4.0 ** rng.random((n, 5))
    ]
    P = np.ascontiguousarray(np.stack([kernel_params(b) for b in bodies], axis=1))
    st = env_stepper("DOP853-numba")
    for energy_tol in (np.inf, 1e-3):
        OUT, S, NF = np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)
        DOP853Batch(n)(Y, U, P, 0.05, 1e-11, 1e-11, energy_tol, OUT, S, NF)
        for k in range(n):
            out, counters = np.empty(11), np.zeros(3, np.int64)
            status = st.step_counted(Y[:, k].copy(), U[:, k].copy(), P[:, k].copy(), 0.05, 0.05, 1e-11, 1e-11,
                                     energy_tol, out, counters)  # fmt: skip
            assert S[k] == status and NF[k] == counters[0], k
            np.testing.assert_array_equal(OUT[:, k], out)
        if energy_tol == np.inf:
            assert (NF > 13).sum() > 20 and S[5] != 0
    one = kernel_params(default_body())
    a = [np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)]
    b = [np.empty_like(Y), np.zeros(n, np.int64), np.zeros(n, np.int64)]
    DOP853Batch(n)(Y, U, one, 0.05, 1e-11, 1e-11, np.inf, *a)
    DOP853Batch(n)(Y, U, np.repeat(one[:, None], n, axis=1), 0.05, 1e-11, 1e-11, np.inf, *b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    OUT, S, NF = b
    for bad, words in (
        (np.where(np.arange(9)[:, None] == 1, 2.0, P), "J1 = J2"),  # an anisotropic lane
        (np.where(np.arange(9)[:, None] == 3, np.arange(n) % 2, P), "one potential kind"),
        (P[:, :5], r"expected shape \(9,\) or \(9, "),
    ):
        with pytest.raises(ValueError, match=words):
            DOP853Batch(n)(Y, U, bad, 0.05, 1e-11, 1e-11, np.inf, OUT, S, NF)


def test_fused_kernels_are_plain_python_over_arrays():
    """The source of the batch kernels stays plain Python (compiled by jit_copy, reusable for other targets)."""
    for name in ("rhs_lanes", "combine_lanes", "dop853_lanes", "dop853_batch_env_step", "dop853_redo_lanes"):
        assert not hasattr(getattr(batch_kernels, name), "py_func")


def test_fused_step_refuses_an_anisotropic_body_and_energy_checks_go_scalar():
    P = kernel_params(default_body()).copy()
    Y, U = _lanes(8, 1)
    OUT, S, NF = np.empty_like(Y), np.zeros(8, np.int64), np.zeros(8, np.int64)
    bad = P.copy()
    bad[1] = 2.0 * bad[0]
    with pytest.raises(ValueError, match="P"):
        DOP853Batch(8)(Y, U, bad, 0.05, 1e-11, 1e-11, np.inf, OUT, S, NF)
    DOP853Batch(8)(Y, U, P, 0.05, 1e-11, 1e-11, 1e-3, OUT, S, NF)  # energy check: every lane through the scalar kernel
    st = env_stepper("DOP853-numba")
    for k in range(8):
        out, counters = np.empty(11), np.zeros(3, np.int64)
        assert S[k] == st.step_counted(Y[:, k].copy(), U[:, k].copy(), P, 0.05, 0.05, 1e-11, 1e-11, 1e-3, out, counters)
        np.testing.assert_array_equal(OUT[:, k], out)


def test_stage_sums_over_the_nonzero_coefficients_equal_the_full_sums_bitwise():
    """The kernels sum DOP853's stages over the nonzero coefficients only: for finite stage values
    (signed zeros, tiny and huge ones included) every sum is bit for bit the sum over all coefficients."""
    from flatbody_env.integrators.dop853_tableau import ERROR_E3, ERROR_E5, ERROR_J, STAGE_C, STAGE_J, STAGE_L, dop

    rng = np.random.default_rng(3)
    K = rng.standard_normal((2000, 13)) * 10.0 ** rng.integers(-150, 150, (2000, 13))
    K[rng.random(K.shape) < 0.1] = 0.0
    K[rng.random(K.shape) < 0.1] = -0.0
    rows = [dop.A[s, :12] for s in range(12)] + [dop.B]
    for r, row in enumerate(rows):
        for k in K[:200]:
            full = 0.0
            for j, c in enumerate(row):
                full += k[j] * c
            part = 0.0
            for q in range(STAGE_L[r]):
                part += k[STAGE_J[r, q]] * STAGE_C[r, q]
            assert np.float64(full).tobytes() == np.float64(part).tobytes()
    assert STAGE_L.sum() < sum(len(r) for r in rows) * 0.8  # a quarter of the products are skipped
    for k in K:
        f5 = f3 = p5 = p3 = 0.0
        for j in range(13):
            f5 += k[j] * dop.E5[j]
            f3 += k[j] * dop.E3[j]
        for q, j in enumerate(ERROR_J):
            p5 += k[j] * ERROR_E5[q]
            p3 += k[j] * ERROR_E3[q]
        assert (f5, f3) == (p5, p3) and np.signbit(f5) == np.signbit(p5)
