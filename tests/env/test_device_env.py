"""The env step and resets as device kernels (:mod:`flatbody_env.env.device`): the counter-based generator, the resets'
distributions against FlatBody-v0's sampler (10⁴ draws), the whole step against FlatBodyVectorEnv bit for bit (CPU
compile of the same source), and the CUDA kernels under numba's CUDA simulator bit for bit against the CPU compile
(a child process: the simulator must be switched on before numba.cuda is imported). Real-GPU checks carry ``gpu``.

Run as a script (``NUMBA_ENABLE_CUDASIM=1 python tests/env/test_device_env.py``) it prints the simulator report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _batch(n, *, max_steps=400, same_step=True, backend="cpu", **kw):
    from flatbody_env.env.device import DeviceBatch
    from flatbody_env.env.env import FlatBodyEnv

    return DeviceBatch(FlatBodyEnv(**kw), n, max_steps, same_step=same_step, backend=backend)


# --------------------------------------------------------------------------------------------- generator
def test_philox_known_answers():
    """Random123's known-answer vectors of Philox-4x32-10."""
    from flatbody_env.env.device import philox4x32

    m = 0xFFFFFFFF
    assert [int(x) for x in philox4x32(0, 0, 0, 0, 0, 0)] == [0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8]
    assert [int(x) for x in philox4x32(m, m, m, m, m, m)] == [0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD]
    assert [int(x) for x in philox4x32(0xA4093822, 0x299F31D0, 0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344)] == [
        0xD16CFE09,
        0x94FDCCEB,
        0x5001E420,
        0x24126EA1,
    ]


def test_uniforms_are_uniform_and_the_compiled_twin_agrees():
    from scipy import stats

    from flatbody_env.env.device import uniform_at
    from flatbody_env.integrators.jit import retarget

    fast = retarget(uniform_at)
    u = np.array([fast(7, 9, b, e, 0, j) for b in range(20) for e in range(5) for j in range(100)])
    assert 0.0 <= u.min() and u.max() < 1.0
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    assert [uniform_at(7, 9, 3, 1, 0, j) for j in range(5)] == [fast(7, 9, 3, 1, 0, j) for j in range(5)]


# --------------------------------------------------------------------------------------------- resets
def test_device_reset_is_the_cpu_sampler_on_the_same_uniforms():
    """Body b's episode = sample_episodes (the CPU env's compiled reset) fed uniform j of the body's Philox stream as its
    j-th number, with the exact test answering "reject" (the device rejects the table's unsure shapes): bit for bit."""
    from flatbody_env.env import compiled
    from flatbody_env.env.device import uniform_at
    from flatbody_env.env.sampling import DECIDE_REJECT, MAX_ATTEMPTS
    from flatbody_env.integrators.jit import retarget

    n = 48
    d = _batch(n)
    d.reset(seed=11)
    sampler = d.p.sampler
    fast = retarget(uniform_at)
    k = 3 * MAX_ATTEMPTS + 12
    D = np.array([[fast(d.key[0], d.key[1], b, 0, 0, j) for j in range(k)] for b in range(n)])
    Y, TG = np.zeros((11, n)), np.empty((n, 6))
    used, codes, cand = np.empty(n, np.int64), np.empty(n, np.int64), np.empty((n, 10))
    compiled.sample_episodes(
        D,
        np.full(n, k, np.int64),
        sampler.cfg,
        sampler.P,
        *sampler.table,
        np.full((n, MAX_ATTEMPTS), DECIDE_REJECT, np.int64),
        Y,
        np.arange(n),
        TG,
        used,
        np.empty((7, 4)),
        codes,
        cand,
    )
    assert (used > 0).all()
    assert np.array_equal(Y, d.Y) and np.array_equal(TG[:, :4].T, d.T)
    assert (d.I[1] == 1).all() and (d.I[0] == 0).all()


def test_device_reset_distributions_match_flatbody_v0():
    """10⁴ resets on the device kernels (CPU compile) against 10⁴ of FlatBodyVectorEnv (FlatBody-v0's sampler: numpy
    generators, the table and the exact test): two-sample KS on every target entry, the aspect and every start entry."""
    from scipy import stats

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    n = 10_000
    v = FlatBodyVectorEnv(num_envs=n)
    v.reset(seed=0)
    d = _batch(n)
    d.reset(seed=0)
    Tc, Td = v.target_vectors.T, d.T
    pairs = [(Tc[k], Td[k]) for k in (0, 1, 3)] + [(Tc[0] / Tc[1], Td[0] / Td[1])]
    Yc = v.states.T
    pairs += [(Yc[k], d.Y[k]) for k in range(11)]
    pvalues = [stats.ks_2samp(a, b).pvalue for a, b in pairs]
    assert min(pvalues) > 1e-3, pvalues
    assert np.all(Td[2] == Tc[2, 0])  # ϱ* is the body's constant
    assert abs((d.Y[2] > 0).mean() - (Yc[2] > 0).mean()) < 0.03  # the sign of (s3*, p_θ*)


def test_seeded_resets_repeat_and_masks_reset_only_their_bodies():
    d = _batch(8)
    d.reset(seed=4)
    Y0 = d.Y.copy()
    d.reset(seed=4)
    assert np.array_equal(d.Y, Y0)
    d.reset()  # no seed: the next episodes
    assert not np.array_equal(d.Y, Y0) and (d.I[1] == 2).all()
    mask = np.zeros(8, np.uint8)
    mask[[1, 5]] = 1
    before = d.Y.copy()
    d.reset(seed=4, mask=mask)
    assert np.array_equal(d.Y[:, [1, 5]], Y0[:, [1, 5]])
    keep = np.ones(8, bool)
    keep[[1, 5]] = False
    assert np.array_equal(d.Y[:, keep], before[:, keep])
    d.reset(seed=4, stagger=True)
    assert (d.I[0] >= 0).all() and (d.I[0] < 400).all() and len(set(d.I[0].tolist())) > 1


# --------------------------------------------------------------------------------------------- step
@pytest.mark.parametrize("same_step", [True, False])
def test_device_step_equals_flatbody_vector_env(same_step):
    """From the CPU env's states, targets and staggered clocks, the same actions: observations, rewards, terms,
    distances, energies, nfev, ends and final observations bit for bit (the bodies' new episodes differ: other draws)."""
    from gymnasium.vector import AutoresetMode

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    n, top = 12, 6
    mode = AutoresetMode.SAME_STEP if same_step else AutoresetMode.NEXT_STEP
    v = FlatBodyVectorEnv(num_envs=n, max_episode_steps=top, autoreset_mode=mode)
    v.reset(seed=2)
    clocks = np.arange(n) % top
    v.set_episode_steps(clocks)
    d = _batch(n, max_steps=top, same_step=same_step)
    d.reset(seed=2)
    d.Y[:] = v.states.T
    d.T[:] = v.target_vectors.T
    d.I[0] = clocks
    rng = np.random.default_rng(1)
    fresh = np.zeros(n, bool)  # bodies whose current episode the two envs drew differently (other generators)
    ended = 0
    for _ in range(4):
        resetting = d.ENDS[2].astype(bool)  # NEXT_STEP: reset in this step, with other draws
        A = rng.uniform(-1.1, 1.1, (n, 4)).astype(np.float32)  # some outside [-1, 1]: clipped
        obs, rew, term, trunc, info = v.step(A)
        d.step(A)
        done = term | trunc
        same = ~fresh
        assert np.array_equal(d.ENDS[0][same].astype(bool), term[same]) and np.array_equal(
            d.ENDS[1][same].astype(bool), trunc[same]
        )
        assert np.array_equal(d.INFO[0][same], rew[same])
        for k, name in enumerate(v.reward_names):
            assert np.array_equal(d.INFO[1 + k][same], info["reward_terms"][name][same])
        stepped = same & ~resetting
        rows = stepped & ~done if same_step else stepped
        assert np.array_equal(d.OBS[rows], obs[rows])
        assert np.array_equal(d.INFO[7][stepped], info["distance"][stepped]) and np.array_equal(
            d.INFO[8][stepped], info["energy"][stepped]
        )
        assert np.array_equal(d.I[3][same], info["integrator"]["nfev"][same]) and np.array_equal(
            d.INFO[11][same], info["t"][same]
        )
        if same_step:
            assert np.array_equal(d.FINAL[stepped & done], info["final_obs"][stepped & done])
            fresh |= done
        else:
            fresh |= resetting
        ended += int((done & same).sum())
    assert ended >= 2 and (~fresh).sum() >= 4


def test_next_step_mode_resets_in_the_step_after_the_end():
    d = _batch(3, max_steps=2, same_step=False)
    d.reset(seed=0)
    A = np.zeros((3, 4), np.float32)
    d.step(A)
    d.step(A)
    assert d.ENDS[1].all() and d.ENDS[2].all() and (d.I[1] == 1).all()
    d.step(A)
    assert not d.ENDS[:2].any() and (d.INFO[:7] == 0).all() and (d.I[1] == 2).all() and (d.I[0] == 0).all()


def test_non_finite_actions_and_unsupported_configurations_raise():
    d = _batch(3)
    d.reset(seed=0)
    A = np.zeros((3, 4), np.float32)
    A[1, 2] = np.nan
    Y = d.Y.copy()
    with pytest.raises(ValueError, match="actions: must be finite"):
        d.step(A)
    assert np.array_equal(d.Y[:, 1], Y[:, 1]) and d.FLAGS[0] == 0
    with pytest.raises(ValueError, match="actions: expected shape"):
        d.step(np.zeros((2, 4)))
    with pytest.raises(ValueError, match="task"):
        _batch(2, task="hold-unstable")
    with pytest.raises(ValueError, match="integrator"):
        _batch(2, integrator="RK45")


# --------------------------------------------------------------------------------------------- simulator
def simulator_report() -> dict:
    """The CUDA kernels (numba's simulator) against the CPU compile of the same source: 3 bodies, both autoreset modes,
    a seeded reset, 3 steps with a 2-step horizon (truncations and autoresets inside the step kernel), a masked and
    staggered reset; the largest difference of every array after every launch."""
    from flatbody_env.integrators import cuda

    report = {"simulated": cuda.simulated(), "device": cuda.device_name(), "modes": {}}
    names = ("Y", "T", "OBS", "FINAL", "INFO", "I", "ENDS")
    for same in (True, False):
        c = _batch(3, max_steps=2, same_step=same)
        g = _batch(3, max_steps=2, same_step=same, backend="cuda")
        g.threads_per_block = 2

        def diff():
            return max(float(np.max(np.abs(c.host(k).astype(float) - g.host(k).astype(float)))) for k in names)

        c.reset(seed=5)
        g.reset(seed=5)
        diffs = [diff()]
        rng = np.random.default_rng(0)
        for _ in range(3):
            A = rng.uniform(-1, 1, (3, 4)).astype(np.float32)
            c.step(A)
            g.step(cuda.cuda.to_device(A))
            diffs.append(diff())
        episodes = g.host("I")[1].tolist()
        mask = np.array([1, 0, 1], np.uint8)
        c.reset(seed=6, mask=mask, stagger=True)
        g.reset(seed=6, mask=cuda.cuda.to_device(mask), stagger=True)
        diffs.append(diff())
        A = np.zeros((3, 4), np.float32)
        A[0, 0] = np.inf
        try:
            g.step(cuda.cuda.to_device(A))
            action_error = ""
        except ValueError as exc:
            action_error = str(exc)
        report["modes"]["same_step" if same else "next_step"] = {
            "diffs": diffs,
            "episodes": episodes,
            "ends": int(c.host("ENDS")[:2].sum()),
            "action_error": action_error,
        }
    return report


@pytest.fixture(scope="module")
def report():
    env = dict(
        os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run([sys.executable, __file__], capture_output=True, text=True, cwd=ROOT, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_cuda_env_kernels_equal_the_cpu_kernels_under_the_simulator(report, mode):
    assert report["simulated"] and report["device"] == "simulator"
    r = report["modes"][mode]
    assert r["diffs"] == [0.0] * len(r["diffs"])
    assert min(r["episodes"]) >= 2  # autoresets (and the masked reset) ran inside the kernels
    assert "actions: must be finite" in r["action_error"]


# --------------------------------------------------------------------------------------------- a real GPU
def _real_gpu() -> bool:
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
        return False
    torch = pytest.importorskip("torch")
    from flatbody_env.integrators import cuda

    return torch.cuda.is_available() and cuda.is_available()


@pytest.mark.gpu
def test_torch_env_on_cuda_follows_the_cpu_kernels():
    """On a CUDA GPU: the torch env (zero-copy tensors) and the CPU compile of the same kernels, same seed, same
    actions: the same draws (the generator is a function of its counters), states to 1e-9 (FMA on the GPU), the same ends."""
    if not _real_gpu():
        pytest.skip("no CUDA GPU here")
    import torch

    from flatbody_env import FlatBodyTorchVectorEnv

    n = 1024
    env = FlatBodyTorchVectorEnv(n, device="cuda", max_episode_steps=20)
    obs, info = env.reset(seed=3)
    ref = _batch(n, max_steps=20)
    ref.reset(seed=3)
    assert obs.device.type == "cuda" and obs.dtype == torch.float32
    assert np.allclose(env.target_vectors.cpu().numpy(), ref.T.T, rtol=0, atol=1e-12)  # same draws; FMA round-off
    rng = np.random.default_rng(0)
    for _ in range(25):
        A = rng.uniform(-1, 1, (n, 4)).astype(np.float32)
        obs, rew, term, trunc, info = env.step(torch.from_numpy(A).cuda())
        ref.step(A)
        assert np.array_equal(trunc.cpu().numpy(), ref.ENDS[1].astype(bool))
        assert np.max(np.abs(env.states.cpu().numpy() - ref.Y.T)) <= 1e-9
        assert np.max(np.abs(rew.cpu().numpy() - ref.INFO[0])) <= 1e-6
    assert "final_obs" in info and info["_final_obs"].dtype == torch.bool


if __name__ == "__main__":
    print(json.dumps(simulator_report()))
