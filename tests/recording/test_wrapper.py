"""The gym wrapper ``RerunRecorder`` — the one way an env episode is recorded."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from flatbody_env.recording.geometry import rotation_from_quaternions
from flatbody_env.recording.reader import read_recording, verify_recording
from flatbody_env.recording.wrapper import RerunRecorder
from recording_oracles import FakeFlatBodyEnv, SCALARS, phi_of, series
import recording_oracles as oracles

strict_rerun = oracles.strict_rerun
scene = oracles.scene
recorded = oracles.recorded  # fixtures


def test_wrapper_records_episodes_in_blocks(tmp_path):
    env = RerunRecorder(FakeFlatBodyEnv(n_steps=23), tmp_path / "ep.rrd", block=7, tensor_every=5)
    rng = np.random.default_rng(0)
    actions = []
    env.reset(seed=1)
    done = False
    while not done:
        a = rng.uniform(-1, 1, 4).astype(np.float32)
        actions.append(a)
        _, _, term, trunc, _ = env.step(a)
        done = term or trunc
    assert env.recorded_paths == [tmp_path / "ep.rrd"]  # finished at termination
    env.reset(seed=2)  # second episode, cut short by close()
    for _ in range(5):
        env.step(np.zeros(4, np.float32))
    env.close()
    assert env.recorded_paths == [tmp_path / "ep.rrd", tmp_path / "ep-1.rrd"]
    for p in env.recorded_paths:
        verify_recording(p)

    data = read_recording(tmp_path / "ep.rrd")
    fake = FakeFlatBodyEnv(n_steps=23)
    np.testing.assert_array_equal(data["/world/body"].step, np.arange(24))  # reset + 23 steps
    np.testing.assert_allclose(data["/world/body"].sim_time, fake._traj.t, atol=1e-9)
    np.testing.assert_array_equal(series(data, "lambda"), fake._traj.state["lambda"])
    np.testing.assert_array_equal(data["/tensors/G"].step, np.arange(0, 24, 5))
    acts = np.array(actions, dtype=np.float64)
    for i, name in enumerate(("tau1", "tau2", "tau3", "f_rho")):
        e = data[f"/series/action/{name}"]
        np.testing.assert_array_equal(e.step, np.arange(1, 24))  # actions at the step they lead to
        np.testing.assert_array_equal(e.components[SCALARS][:, 0], acts[:, i])
    shape = series(data, "reward/shape")
    np.testing.assert_allclose(shape, -np.abs(fake._traj.state["lambda"][1:] - 1.2))
    total = series(data, "reward/total")
    np.testing.assert_allclose(total, shape + series(data, "reward/effort"))
    assert set(e for e in data.entities if e.startswith("/series/target/")) == {f"/series/target/{k}" for k in ("lambda", "mu", "rho", "s3")}
    np.testing.assert_array_equal(data["/series/target/s3"].step, np.arange(24))
    assert "/events" not in data.entities
    assert ("TimeSeries", "reward terms") in data.views and ("TimeSeries", "actions u = (τ₁, τ₂, τ₃, f_ϱ)") in data.views
    # the distance comes from info (the fake env has none): no distance series, nothing invented
    assert "/series/distance" not in data.entities
    second = read_recording(tmp_path / "ep-1.rrd")
    np.testing.assert_array_equal(second["/world/body"].step, np.arange(6))


def test_wrapper_skips_and_notes_a_failed_step(tmp_path):
    env = RerunRecorder(FakeFlatBodyEnv(n_steps=10, fail_at=6), tmp_path / "ep{episode:02d}.rrd", block=4)
    env.reset()
    for _ in range(8):
        env.step(np.zeros(4, np.float32))
    env.close()
    assert env.recorded_paths == [tmp_path / "ep00.rrd"]
    data = read_recording(tmp_path / "ep00.rrd")
    np.testing.assert_array_equal(data["/world/body"].step, np.arange(6))
    np.testing.assert_array_equal(data["/events"].step, [6, 7, 8])
    assert "integration failure" in data["/events"].components["TextLog:text"][0][0]


def test_wrapper_names_a_broken_contract(tmp_path):
    class NoRotation(FakeFlatBodyEnv):
        rotation = None

    env = RerunRecorder(NoRotation(n_steps=3), tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="env.unwrapped.rotation"):
        env.reset()
    assert not (tmp_path / "x.rrd").exists()


def test_wrapper_on_flatbody_v0(tmp_path):
    from flatbody_env.env.task import REWARD_TERMS

    env = RerunRecorder(gym.make("FlatBody-v0", track_rotation=True, max_episode_steps=30), tmp_path / "fb.rrd", block=8)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    steps = 0
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
        steps += 1
        done = term or trunc
    env.close()
    assert env.recorded_paths == [tmp_path / "fb.rrd"]
    verify_recording(tmp_path / "fb.rrd")
    data = read_recording(tmp_path / "fb.rrd")
    np.testing.assert_array_equal(data["/world/body"].step, np.arange(steps + 1))
    np.testing.assert_allclose(data["/world/body"].sim_time[1:] - data["/world/body"].sim_time[:-1], 0.05, atol=1e-9)
    assert {e for e in data.entities if e.startswith("/series/action/")} == {f"/series/action/{n}" for n in ("tau1", "tau2", "tau3", "f_rho")}
    assert {e for e in data.entities if e.startswith("/series/reward/")} == {f"/series/reward/{n}" for n in (*REWARD_TERMS, "total")}
    assert {"/series/target/lambda", "/series/target/s3"} <= set(data.entities)
    # G, C from the logged λ, μ, ϱ, θ and quaternions, as for scene recordings
    lam, mu, rho, theta = (series(data, k) for k in ("lambda", "mu", "rho", "theta"))
    R = rotation_from_quaternions(data["/world/body"].components["Ellipsoids3D:quaternions"][:, 0, :])
    Phi = phi_of(lam, mu, rho, theta, R)
    np.testing.assert_allclose(data["/tensors/G"].components["Tensor:data"], np.swapaxes(Phi, 1, 2) @ Phi, atol=1e-5, rtol=1e-5)
    np.testing.assert_allclose(data["/tensors/C"].components["Tensor:data"], np.linalg.inv(Phi @ np.swapaxes(Phi, 1, 2)), atol=1e-5, rtol=1e-5)
    # a torque-only env names three actions
    env = RerunRecorder(gym.make("FlatBody-v0", control="torque", track_rotation=True), tmp_path / "tq.rrd")
    env.reset(seed=0)
    env.step(np.zeros(3, np.float32))
    env.close()
    data = read_recording(tmp_path / "tq.rrd")
    assert {e for e in data.entities if e.startswith("/series/action/")} == {f"/series/action/{n}" for n in ("tau1", "tau2", "tau3")}


def test_flatbody_v0_without_rotation_tracking_is_named(tmp_path):
    env = RerunRecorder(gym.make("FlatBody-v0"), tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="track_rotation=True"):
        env.reset(seed=0)


def test_wrapper_columns_equal_step_by_step_appends(tmp_path):
    """The wrapper keeps raw steps and converts them together; the same episode appended step by
    step through ``Recorder.append`` (each step converted alone) gives the same file content."""
    from flatbody_env.recording.writer import Recorder

    env = RerunRecorder(gym.make("FlatBody-v0", track_rotation=True, max_episode_steps=60), tmp_path / "batched.rrd")
    u = env.unwrapped
    obs, info = env.reset(seed=4)
    target = dict(u.target)
    rec = Recorder(tmp_path / "stepwise.rrd", u.body, episode=True, block=1000, action_names=("tau1", "tau2", "tau3", "f_rho"),
                   extent=max([u.state[k] for k in ("lambda", "mu", "rho")] + [target[k] for k in ("lambda", "mu", "rho")]))
    rec.append(u.time, u.state, u.rotation, step=0, target=u.target, distance=info["distance"])
    rng = np.random.default_rng(4)
    k, done = 0, False
    while not done:
        a = rng.uniform(-1, 1, 4).astype(np.float32)
        _, reward, term, trunc, info = env.step(a)
        k += 1
        rec.append(u.time, u.state, u.rotation, step=k, action=a, reward_terms={**info["reward_terms"], "total": reward},
                   target=u.target, distance=info["distance"])
        done = term or trunc
    env.close()
    rec.close()
    batched, stepwise = read_recording(tmp_path / "batched.rrd"), read_recording(tmp_path / "stepwise.rrd")
    assert set(batched.entities) == set(stepwise.entities) and len(batched.entities) >= 40
    for name, e in stepwise.entities.items():
        b = batched.entities[name]
        np.testing.assert_array_equal(b.step, e.step, err_msg=name)
        np.testing.assert_array_equal(b.sim_time, e.sim_time, err_msg=name)
        assert set(b.components) == set(e.components), name
        for comp, values in e.components.items():
            if isinstance(values, np.ndarray):
                np.testing.assert_array_equal(b.components[comp], values, err_msg=f"{name} {comp}")
            else:
                assert b.components[comp] == values, f"{name} {comp}"
    np.testing.assert_array_equal(series(batched, "action/tau2")[:3], series(stepwise, "action/tau2")[:3])
    assert batched.entities["/series/lambda"].step.size == k + 1
    assert set(batched.static) == set(stepwise.static)
