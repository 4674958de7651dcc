"""rerun recordings: written, read back offline with rerun's own reader, checked against physics.

The logged G and C are compared with G = ΦᵀΦ and C = (ΦΦᵀ)⁻¹ recomputed here from the
logged λ, μ, ϱ, θ and the logged orientation quaternions (Φ = R D U(θ)⁻¹, eqs. (23)–(24),
(33) of the paper; C per erratum E7 of NOTES.md) — built from scratch, not with kinematics.py.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import rerun as rr
import rerun.chunk as rrc

from flatbody_env import load_scene, simulate
from flatbody_env.cli.main import main
from flatbody_env.recording.writer import BODY_ENTITIES, Recorder, TENSOR_ENTRIES, quaternions_xyzw, read_recording, record_arrays, record_trajectory, rotation_from_quaternions, symmetric_entries, verify_recording
from flatbody_env.recording.wrapper import RerunRecorder

N = 201
T_END = 5.0
SCALARS = "Scalars:scalars"


@pytest.fixture(autouse=True)
def strict_rerun():
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(False)


@pytest.fixture(scope="module")
def scene():
    return load_scene("default")


@pytest.fixture(scope="module")
def traj(scene):
    tr = simulate(scene, t_end=T_END, times=np.linspace(0.0, T_END, N), with_rotation=True)
    assert np.abs(tr.rotation[-1] - np.eye(3)).max() > 0.5, "the scene must rotate for the test to mean anything"
    assert abs(tr.state["theta"][-1] - tr.state["theta"][0]) > 1.0
    return tr


@pytest.fixture(scope="module")
def recorded(traj, scene, tmp_path_factory):
    rr.set_strict_mode(True)
    path = tmp_path_factory.mktemp("rec") / "run.rrd"
    out = record_trajectory(traj, scene.body, path, tensor_every=10)
    assert out == path
    return path, read_recording(path)


def _series(data, name):
    return np.asarray(data[f"/series/{name}"].components[SCALARS])[:, 0]


def _U(theta):
    c, s = np.cos(theta), np.sin(theta)
    U = np.zeros(theta.shape + (3, 3))
    U[:, 0, 0], U[:, 0, 1], U[:, 1, 0], U[:, 1, 1], U[:, 2, 2] = c, -s, s, c, 1.0
    return U


def _phi(lam, mu, rho, theta, R):
    D = np.zeros(lam.shape + (3, 3))
    D[:, 0, 0], D[:, 1, 1], D[:, 2, 2] = lam, mu, rho
    return R @ D @ np.swapaxes(_U(theta), 1, 2)


# --------------------------------------------------------------------------------------------------


def test_entities_timelines_and_counts(recorded, traj):
    path, data = recorded
    present = set(data.entities) | set(data.static)
    assert set(BODY_ENTITIES) <= present, set(BODY_ENTITIES) - present
    assert data.application_id == "flatbody"
    assert data.blueprints == 1
    kinds = [c for c, _ in data.views]
    assert kinds.count("3D") == 2 and kinds.count("Tensor") == 2 and kinds.count("TextDocument") == 1
    assert kinds.count("TimeSeries") == 6 and ("TimeSeries", "reward terms") not in data.views
    temporal = [e for e in BODY_ENTITIES if e in data.entities]
    assert "/world/body" in temporal and "/series/G" in temporal
    for ent in temporal:
        e = data.entities[ent]
        expected = np.arange(0, N, 10) if ent.startswith("/tensors/") else np.arange(N)
        np.testing.assert_array_equal(e.step, expected, err_msg=ent)
        np.testing.assert_allclose(e.sim_time, traj.t[expected], atol=1e-9, rtol=0, err_msg=ent)
    # static parts: description, material lines
    text = data.static["/description"]["TextDocument:text"][0][0]
    assert "Φ = R · diag(λ, μ, ϱ) · U(θ)⁻¹" in text and "Scene `default`" in text
    strips = data.static["/world/material/lines"]["LineStrips3D:strips"]
    assert len(strips[0]) == 12 + 2  # rim circle, 12 spokes, normal
    # env-only entities are absent from a scene recording
    assert not any(e.startswith(("/series/action", "/series/reward", "/series/target")) for e in present)


def test_logged_series_equal_the_trajectory(recorded, traj):
    _, data = recorded
    for name in ("lambda", "mu", "rho", "theta", "p_theta"):
        np.testing.assert_array_equal(_series(data, name), traj.state[name], err_msg=name)
    np.testing.assert_array_equal(_series(data, "energy"), traj.energy)
    np.testing.assert_allclose(_series(data, "casimir"), traj.casimir, rtol=1e-14)
    # the ellipsoid: half-sizes (λ, μ, ϱ) and orientation R, stored as float32
    body = data["/world/body"].components
    half = body["Ellipsoids3D:half_sizes"][:, 0, :]
    np.testing.assert_allclose(half, np.stack([traj.state[k] for k in ("lambda", "mu", "rho")], axis=1), rtol=1e-6)
    R_logged = rotation_from_quaternions(body["Ellipsoids3D:quaternions"][:, 0, :])
    np.testing.assert_allclose(R_logged, traj.rotation, atol=2e-6)


def test_logged_G_and_C_equal_recomputed(recorded):
    _, data = recorded
    lam, mu, rho, theta = (_series(data, k) for k in ("lambda", "mu", "rho", "theta"))
    R = rotation_from_quaternions(data["/world/body"].components["Ellipsoids3D:quaternions"][:, 0, :])
    Phi = _phi(lam, mu, rho, theta, R)
    G_ref = np.swapaxes(Phi, 1, 2) @ Phi  # G = ΦᵀΦ
    C_ref = np.linalg.inv(Phi @ np.swapaxes(Phi, 1, 2))  # C = Φ⁻ᵀΦ⁻¹ = (ΦΦᵀ)⁻¹
    for name, ref in (("G", G_ref), ("C", C_ref)):
        tens = data[f"/tensors/{name}"]
        M = tens.components["Tensor:data"]
        assert M.shape == (tens.step.size, 3, 3) and M.dtype == np.float64
        np.testing.assert_allclose(M, ref[tens.step], atol=1e-5, rtol=1e-5, err_msg=name)
        np.testing.assert_allclose(M, np.swapaxes(M, 1, 2), atol=1e-15, err_msg=f"{name} symmetric")
        six = data[f"/series/{name}"].components[SCALARS]
        assert six.shape == (N, len(TENSOR_ENTRIES))
        np.testing.assert_allclose(six, symmetric_entries(ref), atol=1e-5, rtol=1e-5)
        np.testing.assert_array_equal(six[tens.step], symmetric_entries(M))  # same float64 numbers
    # G is not C's transform of D: they differ unless R = U (sanity: the test is not vacuous)
    assert np.abs(G_ref[-1] - np.linalg.inv(C_ref[-1])).max() > 1e-2
    # eigenvalues: λ², μ², ϱ² for G and their inverses for C (eq. (35))
    G = data["/tensors/G"].components["Tensor:data"]
    k = data["/tensors/G"].step
    np.testing.assert_allclose(np.linalg.eigvalsh(G), np.sort(np.stack([lam, mu, rho], 1)[k] ** 2, axis=1), rtol=1e-12)


def test_transform_and_principal_axes(recorded):
    _, data = recorded
    lam, mu, rho = (_series(data, k) for k in ("lambda", "mu", "rho"))
    half = np.stack([lam, mu, rho], axis=1)
    G = data["/series/G"].components[SCALARS]
    C = data["/series/C"].components[SCALARS]
    # Transform3D(mat3x3=Φ) is stored column-major float32
    Phi = data["/world/material"].components["Transform3D:mat3x3"][:, 0, :].reshape(-1, 3, 3).transpose(0, 2, 1).astype(np.float64)
    np.testing.assert_allclose(symmetric_entries(np.swapaxes(Phi, 1, 2) @ Phi), G, atol=2e-5, rtol=2e-5)
    # arrows: eigenvectors of C (spatial) and G (material) with length 1.25 × semi-axis
    for ent, six, power in (("/world/axes_C", C, -2), ("/material/axes_G", G, 2)):
        v = data[ent].components["Arrows3D:vectors"].astype(np.float64)  # (N, 3, 3): row i = axis i
        assert v.shape == (N, 3, 3)
        np.testing.assert_allclose(np.linalg.norm(v, axis=2), 1.25 * half, rtol=1e-6)
        from flatbody_env.recording.writer import symmetric_from_entries

        M = symmetric_from_entries(six)
        Mv = np.einsum("nij,nkj->nki", M, v)
        np.testing.assert_allclose(Mv, v * (half**power)[:, :, None], atol=1e-5)
    # C's axes are R's columns, G's are U's: different frames once θ ≠ 0 and R ≠ 1
    vc = data["/world/axes_C"].components["Arrows3D:vectors"][-1]
    vg = data["/material/axes_G"].components["Arrows3D:vectors"][-1]
    assert np.abs(vc - vg).max() > 0.1


def test_file_is_complete_when_the_call_returns(recorded, tmp_path, scene, traj):
    path, _ = recorded
    assert len(rrc.RrdReader(path).store().stream().to_chunks()) > 10  # store() needs the footer
    assert "verified" in verify_recording(path)
    # the rerun CLI itself
    exe = shutil.which("rerun")
    cmd = [exe] if exe else [sys.executable, "-m", "rerun"]
    proc = subprocess.run(cmd + ["rrd", "verify", str(path)], capture_output=True, text=True, env=dict(os.environ, CI="1"), timeout=120)
    assert proc.returncode == 0, proc.stderr
    # an open recording has no footer yet; a cut file fails verification
    live = tmp_path / "live.rrd"
    rec = Recorder(live, scene.body, block=4)
    for k in range(10):
        rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
    rec.rec.flush()
    with pytest.warns(Warning, match="no footer"), pytest.raises(Exception):
        rrc.RrdReader(live).store()
    rec.close()
    assert len(rrc.RrdReader(live).store().stream().to_chunks()) > 0
    assert read_recording(live)["/world/body"].step.size == 10
    cut = tmp_path / "cut.rrd"
    raw = Path(path).read_bytes()
    cut.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ValueError, match="rerun rrd verify"):
        verify_recording(cut)


def test_quaternions_against_an_independent_conversion():
    from scipy.spatial.transform import Rotation

    rot = Rotation.random(500, random_state=1)
    extra = Rotation.from_rotvec(np.array([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [np.pi / np.sqrt(2), np.pi / np.sqrt(2), 0], [0, 0, 0]]))
    R = np.concatenate([rot.as_matrix(), extra.as_matrix()])
    q = quaternions_xyzw(R)
    ref = Rotation.from_matrix(R).as_quat()
    sign = np.sign(np.sum(q * ref, axis=1))
    np.testing.assert_allclose(q, ref * sign[:, None], atol=1e-12)
    np.testing.assert_allclose(rotation_from_quaternions(q), R, atol=1e-12)


def test_bad_input_is_a_clear_value_error(traj, scene, tmp_path):
    t, Y, R = traj.t, traj.y, traj.rotation
    ok = tmp_path / "x.rrd"
    with pytest.raises(ValueError, match="states: expected shape"):
        record_arrays(t, Y[:, :-1], R, scene.body, ok, energy=traj.energy)
    bad = Y.copy()
    bad[9, 3] = -0.1
    with pytest.raises(ValueError, match="rho must be > 0"):
        record_arrays(t, bad, R, scene.body, ok, energy=traj.energy)
    bad = Y.copy()
    bad[7, 5] = np.nan
    with pytest.raises(ValueError, match="states: must be finite"):
        record_arrays(t, bad, R, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="rotations: must be rotation matrices"):
        record_arrays(t, Y, R * 1.1, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="t: must be non-decreasing"):
        record_arrays(t[::-1], Y, R, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="actions: expected shape"):
        record_arrays(t, Y, R, scene.body, ok, energy=traj.energy, actions=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="path: .*\\.rrd"):
        record_arrays(t, Y, R, scene.body, tmp_path / "x.txt", energy=traj.energy)
    with pytest.raises(ValueError, match="tensor_every"):
        record_arrays(t, Y, R, scene.body, ok, energy=traj.energy, tensor_every=0)
    no_rot = simulate(scene, t_end=0.5)
    with pytest.raises(ValueError, match="traj.rotation"):
        record_trajectory(no_rot, scene.body, ok)


def test_record_arrays_env_columns_and_default_energy(traj, scene, tmp_path):
    n = 40
    t, Y, R = traj.t[:n], traj.y[:, :n], traj.rotation[:n]
    actions = np.linspace(-1, 1, 4 * n).reshape(n, 4)
    terms = {"shape": -np.abs(Y[7] - 1.2), "effort": -np.sum(actions**2, axis=1)}
    path = record_arrays(t, Y, R, scene.body, tmp_path / "env.rrd", actions=actions, reward_terms=terms, target={"lambda": 1.2}, step=np.arange(100, 100 + n))
    data = read_recording(path)
    for i, name in enumerate(("tau1", "tau2", "tau3", "f_rho")):
        np.testing.assert_array_equal(_series(data, f"action/{name}"), actions[:, i])
    np.testing.assert_array_equal(_series(data, "reward/shape"), terms["shape"])
    np.testing.assert_array_equal(_series(data, "target/lambda"), np.full(n, 1.2))
    np.testing.assert_array_equal(data["/world/body"].step, np.arange(100, 100 + n))
    # energy computed by the recorder (eq. (41)) equals the trajectory's
    np.testing.assert_allclose(_series(data, "energy"), traj.energy[:n], rtol=1e-12)


# --------------------------------------------------------------------------------------------------
# env episodes: a fake env that meets the wrapper contract
# --------------------------------------------------------------------------------------------------


class FakeFlatBodyEnv(gym.Env):
    """Meets the RerunRecorder contract; states from flatbody_env.simulate (actions ignored)."""

    metadata = {"render_modes": []}

    def __init__(self, n_steps: int = 23, dt: float = 0.05, fail_at: int | None = None, track_rotation: bool = True):
        sc = load_scene("default")
        self.body = sc.body
        self.n_steps = n_steps
        self.fail_at = fail_at
        self.action_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (11,), np.float64)
        self._traj = simulate(sc, t_end=n_steps * dt, times=np.linspace(0.0, n_steps * dt, n_steps + 1), with_rotation=True)
        self.target = {"lambda": 1.2, "mu": 1.0, "rho": 1.0, "s3": 0.5, "label": "circle"}
        self._k = 0

    @property
    def state(self):
        st = {k: float(v[self._k]) for k, v in self._traj.state.items()}
        if self.fail_at is not None and self._k >= self.fail_at:
            st["lambda"] = float("nan")
        return st

    @property
    def rotation(self):
        return self._traj.rotation[self._k].copy()

    @property
    def time(self):
        return float(self._traj.t[self._k])

    def _obs(self):
        return self._traj.y[:, self._k].copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._k = 0
        return self._obs(), {}

    def step(self, action):
        self._k += 1
        a = np.asarray(action, float)
        terms = {"shape": -abs(self._traj.state["lambda"][self._k] - 1.2), "effort": -0.01 * float(a @ a)}
        terminated = self._k == self.n_steps
        return self._obs(), sum(terms.values()), terminated, False, {"reward_terms": terms}


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
    np.testing.assert_array_equal(_series(data, "lambda"), fake._traj.state["lambda"])
    np.testing.assert_array_equal(data["/tensors/G"].step, np.arange(0, 24, 5))
    acts = np.array(actions, dtype=np.float64)
    for i, name in enumerate(("tau1", "tau2", "tau3", "f_rho")):
        e = data[f"/series/action/{name}"]
        np.testing.assert_array_equal(e.step, np.arange(1, 24))  # actions at the step they lead to
        np.testing.assert_array_equal(e.components[SCALARS][:, 0], acts[:, i])
    shape = _series(data, "reward/shape")
    np.testing.assert_allclose(shape, -np.abs(fake._traj.state["lambda"][1:] - 1.2))
    total = _series(data, "reward/total")
    np.testing.assert_allclose(total, shape + _series(data, "reward/effort"))
    assert set(e for e in data.entities if e.startswith("/series/target/")) == {f"/series/target/{k}" for k in ("lambda", "mu", "rho", "s3")}
    np.testing.assert_array_equal(data["/series/target/s3"].step, np.arange(24))
    assert "/events" not in data.entities
    assert ("TimeSeries", "reward terms") in data.views and ("TimeSeries", "actions") in data.views
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


def test_rerun_off_is_an_error_not_a_missing_file(tmp_path, monkeypatch, traj, scene):
    monkeypatch.setenv("RERUN", "off")
    with pytest.raises(ValueError, match="RERUN"):
        record_trajectory(traj, scene.body, tmp_path / "off.rrd")
    assert not (tmp_path / "off.rrd").exists()


def test_wrapper_names_a_broken_contract(tmp_path):
    class NoRotation(FakeFlatBodyEnv):
        rotation = None

    env = RerunRecorder(NoRotation(n_steps=3), tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="env.unwrapped.rotation"):
        env.reset()
    assert not (tmp_path / "x.rrd").exists()


def test_importing_the_env_layer_and_cli_does_not_import_rerun():
    code = "import sys, flatbody_env, flatbody_env.recording.wrapper, flatbody_env.recording.writer, flatbody_env.cli.main as c; c.build_parser(); print('rerun' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------------------------------
# commands
# --------------------------------------------------------------------------------------------------


def test_record_command(tmp_path, capsys):
    out = tmp_path / "run.rrd"
    assert main(["record", "--scene", "default", "--t-end", "1", "--samples", "51", "--out", str(out), "--verify"]) == 0
    assert "rerun rrd verify: ok" in capsys.readouterr().out
    data = read_recording(out)
    assert data["/series/lambda"].step.size == 51
    assert data["/series/energy"].sim_time[-1] == pytest.approx(1.0)
    assert main(["record-info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "/world/body" in text and "51" in text and "verified" in text


def test_record_command_bad_input(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["record", "--scene", "default", "--out", str(tmp_path / "run.txt")])
    assert exc.value.code == 2
    assert main(["record", "--scene", "no-such-scene", "--out", str(tmp_path / "a.rrd")]) == 2
    assert main(["record-info", str(tmp_path / "missing.rrd")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "out:" in err


def test_record_env_command(tmp_path, capsys):
    gym.register(id="FakeFlatBodyForRecording-v0", entry_point=FakeFlatBodyEnv, kwargs={"n_steps": 12})
    try:
        out = tmp_path / "env.rrd"
        assert main(["record-env", "--env-id", "FakeFlatBodyForRecording-v0", "--episodes", "2", "--policy", "random", "--out", str(out), "--verify"]) == 0
        printed = capsys.readouterr().out
        assert str(out) in printed and str(tmp_path / "env-1.rrd") in printed
        data = read_recording(tmp_path / "env-1.rrd")
        assert data["/series/action/tau1"].step.size == 12
        assert np.all(np.abs(data["/series/action/tau1"].components[SCALARS]) <= 1.0)
        assert main(["record-env", "--env-id", "NoSuchEnv-v0", "--out", str(out)]) == 2
        assert "env-id" in capsys.readouterr().err
    finally:
        gym.registry.pop("FakeFlatBodyForRecording-v0", None)


# --------------------------------------------------------------------------------------------------
# the real FlatBody-v0
# --------------------------------------------------------------------------------------------------


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
    lam, mu, rho, theta = (_series(data, k) for k in ("lambda", "mu", "rho", "theta"))
    R = rotation_from_quaternions(data["/world/body"].components["Ellipsoids3D:quaternions"][:, 0, :])
    Phi = _phi(lam, mu, rho, theta, R)
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


def test_record_env_command_on_flatbody_v0(tmp_path, capsys):
    out = tmp_path / "fb.rrd"
    assert main(["record-env", "--episodes", "1", "--max-steps", "20", "--policy", "random", "--out", str(out), "--verify"]) == 0
    data = read_recording(out)
    assert data["/series/lambda"].step.size == 21
    assert data["/series/reward/total"].step.size == 20
