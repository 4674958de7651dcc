"""The one transition (:mod:`flatbody_env.env.transition`) on every face: the counter-based generator, the seed
convention (body i of a batch seeded s draws what a single env seeded s + i draws), every v1 id equal on the single
env, the vector env (both autoreset modes, split over threads), the torch env on the CPU and the CUDA kernels under
numba's CUDA simulator (a child process: the simulator must be switched on before numba.cuda is imported), the v1
draws' distributions against the v0 sampler's, and the v0 ids unchanged by the rewrite (their saved numbers).

Run as a script (``NUMBA_ENABLE_CUDASIM=1 python tests/env/test_transition.py``) it prints the simulator report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _v1_kwargs(env_id: str, *, short_witness: bool = False) -> dict:
    from flatbody_env.env.registration import task_spec

    kw = dict(task_spec(env_id).kwargs)
    if short_witness and kw.get("task") == "reach-witnessed":  # keep the simulator's (pure Python) resets short
        kw.update(witness_steps=40, start_distance=(0.0, 0.5), min_uncontrolled_offset=0.0)
    return kw


# --------------------------------------------------------------------------------------------- generator
def test_philox_known_answers():
    """Random123's known-answer vectors of Philox-4x32-10."""
    from flatbody_env.env.transition import philox4x32

    m = 0xFFFFFFFF
    assert [int(x) for x in philox4x32(0, 0, 0, 0, 0, 0)] == [0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8]
    assert [int(x) for x in philox4x32(m, m, m, m, m, m)] == [0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD]
    assert [int(x) for x in philox4x32(0xA4093822, 0x299F31D0, 0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344)] == [
        0xD16CFE09,
        0x94FDCCEB,
        0x5001E420,
        0x24126EA1,
    ]


def test_uniforms_are_uniform_independent_across_seeds_and_the_compiled_twin_agrees():
    from scipy import stats

    from flatbody_env.env.transition import seed_key, uniform_at
    from flatbody_env.integrators.jit import retarget

    fast = retarget(uniform_at)
    keys = [seed_key(s) for s in range(20)]
    u = np.array([[fast(k0, k1, e, 0, j) for e in range(5) for j in range(100)] for k0, k1 in keys])
    assert u.min() >= 0.0 and u.max() < 1.0
    assert stats.kstest(u.ravel(), "uniform").pvalue > 1e-3
    # neighbouring seeds (0, 1, 2, ...) give uncorrelated streams
    c = np.corrcoef(u)
    assert np.max(np.abs(c - np.eye(20))) < 0.25
    k0, k1 = keys[3]
    assert [uniform_at(k0, k1, 1, 0, j) for j in range(5)] == [fast(k0, k1, 1, 0, j) for j in range(5)]


# --------------------------------------------------------------------------------------------- faces
def _rollout_single(env_id: str, seed: int, actions: np.ndarray):
    import gymnasium as gym

    env = gym.make(env_id).unwrapped
    obs, _ = env.reset(seed=seed)
    rows = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        rows.append(
            np.concatenate([obs, [np.float32(r), info["distance"], float(term)]])
        )  # the torch env's rewards: float32
        if term:
            break
    return rows


@pytest.mark.parametrize(
    "env_id", ["FlatBody-v1", "FlatBodyHoldUnstable-v1", "FlatBodyTorque-v1", "FlatBodyAnyBody-v1"]
)
def test_body_i_of_a_batch_seeded_s_is_a_single_env_seeded_s_plus_i(env_id):
    """Gymnasium's convention, bit for bit, for the transition's own draws: N single envs = one vector env = the same
    vector env split over two threads = the torch env on the CPU."""
    import torch

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    n, steps = 4, 25
    kw = _v1_kwargs(env_id)
    rng = np.random.default_rng(1)
    venv = FlatBodyVectorEnv(n, max_episode_steps=1000, **kw)
    A = rng.uniform(-1, 1, (steps, n, venv.single_action_space.shape[0]))
    singles = [_rollout_single(env_id, 70 + i, A[:, i]) for i in range(n)]
    threaded = FlatBodyVectorEnv(n, max_episode_steps=1000, num_threads=2, **kw)
    tenv = FlatBodyTorchVectorEnv(n, device="cpu", max_episode_steps=1000, autoreset_mode="NextStep", **kw)
    outs = []
    for env in (venv, threaded, tenv):
        obs, _ = env.reset(seed=70)
        obs = np.asarray(obs)
        rows = [[obs[i]] for i in range(n)]
        done = np.zeros(n, dtype=bool)
        for k in range(steps):
            a = A[k] if env is not tenv else torch.as_tensor(A[k])
            obs, r, term, trunc, info = env.step(a)
            obs, r, term, d = (np.asarray(x) for x in (obs, r, term, info["distance"]))
            for i in np.flatnonzero(~done):
                rows[i].append(np.concatenate([obs[i], [np.float32(r[i]), d[i], float(term[i])]]))
            done |= term
        outs.append(rows)
    for rows in outs:
        for i in range(n):
            assert len(rows[i]) == len(singles[i])
            for x, y in zip(rows[i], singles[i], strict=True):
                np.testing.assert_array_equal(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))


def test_one_info_schema_on_every_face():
    import gymnasium as gym
    import torch

    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    single = gym.make("FlatBody-v1")
    single.reset(seed=0)
    _, _, _, _, si = single.step(np.zeros(4, np.float32))
    venv = FlatBodyVectorEnv(3, **_v1_kwargs("FlatBody-v1"))
    venv.reset(seed=0)
    _, _, _, _, vi = venv.step(np.zeros((3, 4)))
    tenv = FlatBodyTorchVectorEnv(3, **_v1_kwargs("FlatBody-v1"))
    tenv.reset(seed=0)
    _, _, _, _, ti = tenv.step(torch.zeros(3, 4))
    per_step = {
        "t",
        "distance",
        "is_success",
        "energy",
        "casimir",
        "p_theta",
        "integrator",
        "status",
        "domain_code",
        "reward_terms",
    }
    assert set(si) == per_step
    assert per_step | {"episode", "_episode", "log"} <= set(vi)
    assert set(ti) == set(vi) | {"final_obs", "_final_obs"}
    assert set(si["reward_terms"]) == set(vi["reward_terms"]) == set(ti["reward_terms"]) == {"success", "proximity"}
    assert isinstance(si["status"], int) and vi["status"].dtype == np.int64 and ti["status"].dtype == torch.int64
    assert vi["domain_code"].dtype == np.int64 and ti["domain_code"].dtype == torch.int64
    assert vi["t"].dtype == np.float64 and ti["t"].dtype == torch.float64
    assert set(vi["episode"]) == {"r", "l", "is_success", "distance"}


def test_episode_statistics_and_log_follow_the_episodes():
    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    env = FlatBodyVectorEnv(3, max_episode_steps=5, autoreset_mode="SameStep", **_v1_kwargs("FlatBody-v1"))
    env.reset(seed=3)
    returns = np.zeros(3)
    for k in range(5):
        _, r, term, trunc, info = env.step(np.zeros((3, 4)))
        returns += r
        if k < 4:
            assert not info["_episode"].any() and int(info["log"]["episodes"]) == 0
            quiet = info["log"]
    assert info["_episode"].all() and trunc.all()
    # the same log whether or not an episode ended (keys, 0-d arrays, dtypes)
    assert {k: (v.shape, v.dtype) for k, v in quiet.items()} == {k: (v.shape, v.dtype) for k, v in info["log"].items()}
    # every array handed out is the step's own: none shares memory with the env's state
    core = env.cores[0]
    leaves = [info[k] for k in ("t", "distance", "energy", "casimir", "p_theta", "status", "domain_code")]
    leaves += [*info["reward_terms"].values(), *info["episode"].values(), info["integrator"]["nfev"]]
    assert not any(np.shares_memory(a, core.S) or np.shares_memory(a, core.K) for a in leaves)
    np.testing.assert_allclose(info["episode"]["r"], returns, rtol=0, atol=1e-12)
    assert (info["episode"]["l"] == 5).all()
    np.testing.assert_allclose(info["log"]["episode_return"], returns.mean(), atol=1e-12)
    np.testing.assert_array_equal(info["episode"]["distance"], info["distance"])


def test_the_lanes_rows_lie_an_odd_number_of_cache_lines_apart():
    """Rows a power-of-two multiple of 4 KiB apart share their cache sets: the lanes' layout never puts them so, and
    has one (strided) layout whatever N, so that the compiled loops are compiled once."""
    from flatbody_env.env import transition as tr
    from flatbody_env.env.core import EnvCore, configure

    for n in (1, 7, 8, 63, 512, 1000, 1024, 4096):
        for dtype in (np.float64, np.int64):
            a = tr.lanes(tr.S_ROWS, n, dtype)
            assert a.shape == (tr.S_ROWS, n) and a.dtype == dtype and not a.any()
            assert not a.flags.c_contiguous and a.strides[1] == 8
            assert a.strides[0] % 64 == 0 and (a.strides[0] // 64) % 2 == 1, (n, a.strides)
    core = EnvCore(configure(**_v1_kwargs("FlatBody-v1")), 1024)
    assert all((x.strides[0] // 64) % 2 == 1 for x in (core.S, core.K))


def test_the_tolerance_reward_is_bounded_and_names_its_terms():
    """In [0, 1] per step; ``success`` = 1 − β inside the tolerance, ``proximity`` = β·g(d) (g = 0.1 at the margin)."""
    import gymnasium as gym

    from flatbody_env.env.transition import proximity

    assert proximity(0.04, 0.05, 0.5) == 1.0
    assert proximity(0.55, 0.05, 0.5) == pytest.approx(0.1)
    env = gym.make("FlatBody-v1")
    env.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(60):
        _, r, term, _, info = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
        t = info["reward_terms"]
        assert 0.0 <= r <= 1.0 and r == t["success"] + t["proximity"]
        inside = info["distance"] <= 0.05
        assert t["success"] == (0.8 if inside else 0.0)
        assert t["proximity"] == pytest.approx(0.2 * proximity(info["distance"], 0.05, 0.5), rel=1e-12)


def test_v1_draws_follow_the_v0_samplers_distributions():
    """The same distributions, other numbers: FlatBody-v1's targets and starts against FlatBody-v0's (2,000 draws
    each)."""
    from scipy import stats

    from flatbody_env.env.vector_env import FlatBodyVectorEnv

    n = 2000
    v1 = FlatBodyVectorEnv(n, **_v1_kwargs("FlatBody-v1"))
    v0 = FlatBodyVectorEnv(n, task="reach")
    o1, _ = v1.reset(seed=0)
    o0, _ = v0.reset(seed=0)
    for col in (0, 2, 4, 7, 8, 9, 12, 13, 15):
        assert stats.ks_2samp(o1[:, col], o0[:, col]).pvalue > 1e-4, col


def test_non_finite_actions_refused_and_v0_ids_stay_on_the_cpu():
    import gymnasium as gym

    from flatbody_env.env.core import EnvCore, configure

    env = gym.make("FlatBody-v1")
    env.reset(seed=0)
    before = env.unwrapped.physics_state
    with pytest.raises(ValueError, match="^action: must be finite"):
        env.step(np.array([np.nan, 0, 0, 0], np.float32))
    np.testing.assert_array_equal(before, env.unwrapped.physics_state)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = configure(task="reach")
    core = EnvCore(cfg, 2)
    assert "v1 ids" in core.device_unsupported()


# --------------------------------------------------------------------------------------------- the CUDA simulator
def _simulator_report() -> dict:
    """Every v1 id's CUDA kernels against the CPU loops, under the simulator (run in a child process)."""
    from flatbody_env.env import transition as tr
    from flatbody_env.env.core import EnvCore, configure
    from flatbody_env.env.registration import V1_IDS
    from flatbody_env.integrators import cuda

    dev = cuda.require()
    report = {"simulated": cuda.simulated(), "runs": {}}
    cases = [(env_id, mode, {}) for env_id in V1_IDS for mode in ("same", "next")]
    # the time observed after the body's constants (the observation's 22 columns)
    cases.append(("FlatBodyAnyBody-v1", "next", {"observe_body": True, "observe_time": True}))
    for env_id, mode, extra in cases:
        cfg = configure(**{**_v1_kwargs(env_id, short_witness=True), **extra})
        c = EnvCore(cfg, 3, max_episode_steps=3, autoreset=mode)
        g = EnvCore(cfg, 3, max_episode_steps=3, autoreset=mode, backend="cuda", threads_per_block=2)

        def diff(c=c, g=g):
            return max(
                float(np.max(np.abs(c.host(k).astype(float) - g.host(k).astype(float))))
                for k in ("S", "K", "OBS", "FINAL")
            )

        c.reset(seeds=[5, 6, 7])
        g.reset(seeds=[5, 6, 7])
        diffs = [diff()]
        rng = np.random.default_rng(0)
        for _ in range(4):
            A = rng.uniform(-1, 1, (3, cfg.n_act)).astype(np.float32)
            c.step(A)
            g.step(dev.to_device(A))
            diffs.append(diff())
        episodes = g.host("K")[tr.K_EPISODE].tolist()
        m = np.array([True, False, True])
        c.reset(seeds=[8, 9, 10], mask=m, stagger=True)
        g.reset(seeds=[8, 9, 10], mask=m, stagger=True)
        diffs.append(diff())
        A = np.zeros((3, cfg.n_act), np.float32)
        A[:, 0] = np.inf
        try:
            g.step(dev.to_device(A))
            error = ""
        except ValueError as exc:
            error = str(exc)
        key = f"{env_id}{'+time' if extra else ''}:{mode}"
        report["runs"][key] = {"diffs": diffs, "episodes": episodes, "action_error": error}
        report["runs"][key]["time"] = g.host("OBS")[:, -1].tolist() if extra else None
    return report


@pytest.fixture(scope="module")
def simulator():
    env = dict(
        os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    )
    proc = subprocess.run([sys.executable, __file__], capture_output=True, text=True, cwd=ROOT, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_cuda_kernels_equal_the_cpu_loops_under_the_simulator_for_every_v1_id(simulator):
    from flatbody_env.env.registration import V1_IDS

    assert simulator["simulated"]
    assert sorted(simulator["runs"]) == sorted(
        [f"{e}:{m}" for e in V1_IDS for m in ("same", "next")] + ["FlatBodyAnyBody-v1+time:next"]
    )
    assert max(simulator["runs"]["FlatBodyAnyBody-v1+time:next"]["time"]) > 0  # the clocks observed, staggered
    for key, run in simulator["runs"].items():
        assert run["diffs"] == [0.0] * len(run["diffs"]), key
        assert min(run["episodes"]) >= 1 and max(run["episodes"]) >= 2, key  # autoresets ran inside the kernels
        assert "actions: must be finite" in run["action_error"], key


if __name__ == "__main__":
    print(json.dumps(_simulator_report()))
