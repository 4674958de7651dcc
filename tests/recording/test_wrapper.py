"""The gym wrapper ``RerunRecorder`` — the one way an env episode is recorded."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from flatbody_env.recording.geometry import symmetric_from_entries
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
    np.testing.assert_array_equal(data["/tensors/numbers"].step, np.arange(0, 24, 5))
    acts = np.array(actions, dtype=np.float64)
    for i, name in enumerate(("tau1", "tau2", "tau3", "f_rho")):
        e = data[f"/series/action/{name}"]
        np.testing.assert_array_equal(e.step, np.arange(1, 24))  # actions at the step they lead to
        np.testing.assert_array_equal(e.components[SCALARS][:, 0], acts[:, i])
    shape = series(data, "reward/shape")
    np.testing.assert_allclose(shape, -np.abs(fake._traj.state["lambda"][1:] - 1.2))
    total = series(data, "reward/total")
    np.testing.assert_allclose(total, shape + series(data, "reward/effort"))
    assert set(e for e in data.entities if e.startswith("/series/target/")) == {
        f"/series/target/{k}" for k in ("lambda", "mu", "rho", "s3")
    }
    np.testing.assert_array_equal(data["/series/target/s3"].step, np.arange(24))
    assert "/events" not in data.entities
    assert any(c == "TimeSeries" and n.startswith("reward terms") for c, n in data.views) and any(
        n.startswith("actions in [−1, 1]") for _, n in data.views
    )
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

    env = RerunRecorder(
        gym.make("FlatBody-v0", track_rotation=True, max_episode_steps=30), tmp_path / "fb.rrd", block=8
    )
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
    assert {e for e in data.entities if e.startswith("/series/action/")} == {
        f"/series/action/{n}" for n in ("tau1", "tau2", "tau3", "f_rho")
    }
    assert {e for e in data.entities if e.startswith("/series/reward/")} == {
        f"/series/reward/{n}" for n in (*REWARD_TERMS, "total")
    }
    assert {"/series/target/lambda", "/series/target/s3"} <= set(data.entities)
    # G, C from the logged λ, μ, ϱ, θ and quaternions, as for scene recordings
    lam, mu, rho, theta = (series(data, k) for k in ("lambda", "mu", "rho", "theta"))
    R = rotation_from_quaternions(data["/world/body"].components["Ellipsoids3D:quaternions"][:, 0, :])
    Phi = phi_of(lam, mu, rho, theta, R)
    np.testing.assert_allclose(
        symmetric_from_entries(data["/series/G"].components[SCALARS]),
        np.swapaxes(Phi, 1, 2) @ Phi,
        atol=1e-5,
        rtol=1e-5,
    )
    np.testing.assert_allclose(
        symmetric_from_entries(data["/series/C"].components[SCALARS]),
        np.linalg.inv(Phi @ np.swapaxes(Phi, 1, 2)),
        atol=1e-5,
        rtol=1e-5,
    )
    # a torque-only env names three actions
    env = RerunRecorder(gym.make("FlatBody-v0", control="torque", track_rotation=True), tmp_path / "tq.rrd")
    env.reset(seed=0)
    env.step(np.zeros(3, np.float32))
    env.close()
    data = read_recording(tmp_path / "tq.rrd")
    assert {e for e in data.entities if e.startswith("/series/action/")} == {
        f"/series/action/{n}" for n in ("tau1", "tau2", "tau3")
    }


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
    rec = Recorder(
        tmp_path / "stepwise.rrd",
        u.body,
        episode=True,
        block=1000,
        action_names=("tau1", "tau2", "tau3", "f_rho"),
        extent=max([u.state[k] for k in ("lambda", "mu", "rho")] + [target[k] for k in ("lambda", "mu", "rho")]),
        success_tolerance=u.task.success_tolerance,
    )
    rec.append(u.time, u.state, u.rotation, step=0, target=u.target, distance=info["distance"])
    rng = np.random.default_rng(4)
    k, done = 0, False
    while not done:
        a = rng.uniform(-1, 1, 4).astype(np.float32)
        control = u.controls(a)[1]
        _, reward, term, trunc, info = env.step(a)
        k += 1
        rec.append(
            u.time,
            u.state,
            u.rotation,
            step=k,
            action=a,
            reward_terms={**info["reward_terms"], "total": reward},
            target=u.target,
            distance=info["distance"],
            control=control,
        )
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


def test_step_columns_pad_missing_names_and_see_in_place_changes():
    """The recorder buffers each step's numbers in columns: a name first seen later is NaN before it,
    a name a step lacks is NaN there, bools and non-numbers are left out, ``total`` is the reward
    unless the terms have one, and a dict changed in place between steps is read again."""
    from flatbody_env.recording.writer import _Columns

    c = _Columns()
    c.add({"a": 1.0, "flag": True, "label": "x"}, total=0.5)
    c.add({"a": 2.0, "b": np.float32(3.0)}, total=1.5)
    c.add(None)
    c.add({"b": 4.0, "total": 9.0}, total=2.5)
    cols = c.arrays()
    assert list(cols) == ["a", "total", "b"]
    np.testing.assert_array_equal(cols["a"], [1.0, 2.0, np.nan, np.nan])
    np.testing.assert_array_equal(cols["b"], [np.nan, 3.0, np.nan, 4.0])
    np.testing.assert_array_equal(cols["total"], [0.5, 1.5, np.nan, 9.0])

    target = {"lambda": 1.2, "mu": 1.0, "label": "circle"}
    t = _Columns()
    t.add(target, names=("lambda", "mu"))
    t.add(target, names=("lambda", "mu"))  # the same row again
    target["lambda"] = 1.3  # the env changed its dict in place
    t.add(target, names=("lambda", "mu"))
    t.add({"mu": 0.9}, names=("lambda", "mu"))
    cols = t.arrays()
    assert list(cols) == ["lambda", "mu"]
    np.testing.assert_array_equal(cols["lambda"], [1.2, 1.2, 1.3, np.nan])
    np.testing.assert_array_equal(cols["mu"], [1.0, 1.0, 1.0, 0.9])


def test_wrapper_records_terms_and_targets_that_change_within_an_episode(tmp_path):
    class Changing(FakeFlatBodyEnv):
        def step(self, action):
            obs, reward, term, trunc, info = super().step(action)
            if self._k >= 4:  # a term that appears mid-episode; the target moves in place
                info["reward_terms"]["bonus"] = 0.25
                self.target["lambda"] = 1.4
            return obs, reward, term, trunc, info

    env = RerunRecorder(Changing(n_steps=8), tmp_path / "c.rrd", block=3)
    env.reset()
    done = False
    while not done:
        _, _, term, trunc, _ = env.step(np.zeros(4, np.float32))
        done = term or trunc
    data = read_recording(tmp_path / "c.rrd")
    np.testing.assert_array_equal(data["/series/reward/bonus"].step, np.arange(4, 9))
    np.testing.assert_array_equal(series(data, "reward/bonus"), 0.25)
    np.testing.assert_array_equal(data["/series/reward/shape"].step, np.arange(1, 9))
    np.testing.assert_array_equal(series(data, "target/lambda"), [1.2] * 4 + [1.4] * 5)


def test_wrapper_names_a_physics_state_out_of_order(tmp_path):
    class Shuffled(FakeFlatBodyEnv):
        @property
        def physics_state(self):
            return self._obs()[::-1].copy()

    env = RerunRecorder(Shuffled(n_steps=3), tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="env.unwrapped.physics_state"):
        env.reset()


def test_step_columns_take_rows_with_array_entries():
    from flatbody_env.recording.writer import _Columns

    c = _Columns()
    row = {"lambda": 1.2, "axes": np.array([1.0, 2.0])}
    c.add(row, names=("lambda",))
    c.add(dict(row), names=("lambda",))  # equal keys, an array entry: compared without error
    np.testing.assert_array_equal(c.arrays()["lambda"], [1.2, 1.2])
