"""The torch env on a CUDA GPU against the same env on the CPU, for every v1 id (marked ``gpu``: skipped without one).

Both faces run the one transition (:mod:`flatbody_env.env.transition`): compiled by numba for the CPU, by numba-cuda
for the GPU. The same seed gives the same episodes on both — targets and bodies from the same Philox uniforms, to
round-off (the GPU contracts multiply-adds, so the last bits of a computed number may differ) — and the same steps to
round-off; an episode whose success or failure is decided within that round-off may end a step apart, after which that
body's episodes part ways, so the states are compared on the bodies whose ends agreed throughout (and those are counted).
The kernels themselves are tested without a GPU under numba's CUDA simulator (tests/env/test_transition.py).

``FLATBODY_GPU_REPORT=FILE.json`` also writes the measured differences (per id) to that file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from flatbody_env.env.registration import V1_IDS

pytestmark = pytest.mark.gpu

N = 256
"""Bodies per face."""
HORIZON = 30
"""Steps per episode here (short, so that every body autoresets twice within :data:`STEPS`)."""
STEPS = 70


def _require_gpu():
    torch = pytest.importorskip("torch")
    from flatbody_env.integrators import cuda

    if cuda.simulated() or not torch.cuda.is_available() or not cuda.is_available():
        pytest.skip("no CUDA GPU here")
    return torch


def _report(env_id: str, figures: dict) -> None:
    path = os.environ.get("FLATBODY_GPU_REPORT")
    if not path:
        return
    file = Path(path)
    data = json.loads(file.read_text()) if file.exists() else {}
    data[env_id] = figures
    file.write_text(json.dumps(data, indent=1))


def _schema(info: dict) -> dict:
    out = {}
    for k, v in info.items():
        out[k] = _schema(v) if isinstance(v, dict) else str(getattr(v, "dtype", type(v).__name__))
    return out


def _faces(env_id: str, mode):
    from flatbody_env.env.registration import task_spec
    from flatbody_env.env.torch_vector_env import FlatBodyTorchVectorEnv

    kw = dict(task_spec(env_id).kwargs)
    return [
        FlatBodyTorchVectorEnv(N, device=d, max_episode_steps=HORIZON, autoreset_mode=mode, **kw)
        for d in ("cpu", "cuda")
    ]


def _run(env_id: str, mode) -> dict:
    torch = _require_gpu()
    from flatbody_env.env.registration import task_spec

    cpu, gpu = _faces(env_id, mode)
    o_c, i_c = cpu.reset(seed=1000)
    o_g, i_g = gpu.reset(seed=1000)
    assert _schema(i_c) == _schema(i_g)  # one info schema: the same keys and dtypes on both devices
    witnessed = task_spec(env_id).kwargs.get("task") == "reach-witnessed"
    figures = {
        "reset_target": float((cpu.target_vectors - gpu.target_vectors.cpu()).abs().max()),
        "reset_state": float((cpu.states - gpu.states.cpu()).abs().max()),
        "reset_obs": float((o_c - o_g.cpu()).abs().max()),
        "witnessed": witnessed,
    }
    rng = np.random.default_rng(0)
    agree = np.ones(N, dtype=bool)
    state_diff = obs_diff = 0.0
    resets = 0
    for _ in range(STEPS):
        a = torch.from_numpy(rng.uniform(-1.0, 1.0, (N, *cpu.single_action_space.shape)).astype(np.float32))
        oc, rc, tc, uc, ic = cpu.step(a)
        og, rg, tg, ug, ig = gpu.step(a.cuda())
        assert _schema(ic) == _schema(ig)
        assert og.device.type == "cuda" and rg.dtype == rc.dtype == torch.float32 and tg.dtype == torch.bool
        agree &= (tc == tg.cpu()).numpy() & (uc == ug.cpu()).numpy()
        resets += int((tc | uc).sum())
        if agree.any():
            k = torch.from_numpy(agree)
            state_diff = max(state_diff, float((cpu.states[k] - gpu.states.cpu()[k]).abs().max()))
            obs_diff = max(obs_diff, float((oc[k] - og.cpu()[k]).abs().max()))
    figures.update(steps=STEPS, bodies=N, resets=resets, ends_agree=int(agree.sum()), state=state_diff, obs=obs_diff)
    _report(f"{env_id}:{mode}", figures)
    return figures


@pytest.mark.parametrize("env_id", V1_IDS)
def test_every_v1_id_draws_and_steps_on_the_gpu_as_on_the_cpu(env_id):
    f = _run(env_id, "SameStep")
    assert f["reset_target"] <= 1e-12, f  # the same episodes: targets (and bodies) from the same uniforms
    assert f["reset_state"] <= (1e-9 if f["witnessed"] else 1e-12), f  # a witnessed start is integrated first
    assert f["resets"] >= N  # the autoresets (their draws inside the step kernel) were compared too
    assert f["ends_agree"] >= 0.97 * N, f
    assert f["state"] <= 1e-7 and f["obs"] <= 1e-5, f


def test_next_step_autoreset_and_a_refused_action_on_the_gpu():
    torch = _require_gpu()
    f = _run("FlatBody-v1", "NextStep")
    assert f["reset_target"] <= 1e-12 and f["ends_agree"] >= 0.97 * N and f["state"] <= 1e-7, f
    _, gpu = _faces("FlatBody-v1", "SameStep")
    gpu.reset(seed=0)
    a = torch.zeros(N, 4, device="cuda")
    a[7, 2] = float("nan")
    with pytest.raises(ValueError, match="actions: must be finite.*body 7 was not stepped"):
        gpu.step(a)
    gpu.step(torch.zeros(N, 4, device="cuda"))  # the flag was cleared: the next step runs
