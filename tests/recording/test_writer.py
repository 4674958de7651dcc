"""The writer: a trajectory logged column-wise, read back offline and checked against physics.

The logged G and C are compared with G = ΦᵀΦ and C = (ΦΦᵀ)⁻¹ recomputed from the logged λ, μ, ϱ, θ and
quaternions by the independent oracles of ``recording_oracles``.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from flatbody_env import simulate
from flatbody_env.recording.geometry import (
    TENSOR_ENTRIES,
    rotation_from_quaternions,
    symmetric_entries,
    symmetric_from_entries,
)
from flatbody_env.recording.reader import read_recording
from flatbody_env.recording.writer import BODY_ENTITIES, LABEL_DROP, record_arrays, record_trajectory
from recording_oracles import N, SCALARS, phi_of, series
import recording_oracles as oracles

strict_rerun = oracles.strict_rerun
scene = oracles.scene
traj = oracles.traj
recorded = oracles.recorded  # fixtures


def test_entities_timelines_and_counts(recorded, traj):
    path, data = recorded
    present = set(data.entities) | set(data.static)
    assert set(BODY_ENTITIES) <= present, set(BODY_ENTITIES) - present
    assert data.application_id == "flatbody"
    assert data.blueprints == 1
    kinds = [c for c, _ in data.views]
    assert (
        kinds.count("3D") == 3 and kinds.count("Tensor") == 0 and kinds.count("TextDocument") == 2
    )  # G, C: numbers, no heat map
    assert ("TimeSeries", "reward terms") not in data.views and any(
        n.startswith("conserved: drift") for _, n in data.views
    )
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
    assert "shared/" not in text and "NOTES.md" not in text
    strips = data.static["/world/material/lines"]["LineStrips3D:strips"]
    assert len(strips[0]) == 12 + 2  # rim circle, 12 spokes, normal
    # env-only entities are absent from a scene recording
    assert not any(
        e.startswith(("/series/action", "/series/reward", "/series/target", "/series/distance", "/world/target"))
        for e in present
    )


def test_logged_series_equal_the_trajectory(recorded, traj):
    _, data = recorded
    for name in ("lambda", "mu", "rho", "theta", "p_theta"):
        np.testing.assert_array_equal(series(data, name), traj.state[name], err_msg=name)
    np.testing.assert_array_equal(series(data, "energy"), traj.energy)
    np.testing.assert_allclose(series(data, "casimir"), traj.casimir, rtol=1e-14)
    # the ellipsoid: half-sizes (λ, μ, ϱ) and orientation R, stored as float32
    body = data["/world/body"].components
    half = body["Ellipsoids3D:half_sizes"][:, 0, :]
    np.testing.assert_allclose(half, np.stack([traj.state[k] for k in ("lambda", "mu", "rho")], axis=1), rtol=1e-6)
    R_logged = rotation_from_quaternions(body["Ellipsoids3D:quaternions"][:, 0, :])
    np.testing.assert_allclose(R_logged, traj.rotation, atol=2e-6)


def test_logged_G_and_C_equal_recomputed(recorded):
    _, data = recorded
    lam, mu, rho, theta = (series(data, k) for k in ("lambda", "mu", "rho", "theta"))
    R = rotation_from_quaternions(data["/world/body"].components["Ellipsoids3D:quaternions"][:, 0, :])
    Phi = phi_of(lam, mu, rho, theta, R)
    G_ref = np.swapaxes(Phi, 1, 2) @ Phi  # G = ΦᵀΦ
    C_ref = np.linalg.inv(Phi @ np.swapaxes(Phi, 1, 2))  # C = Φ⁻ᵀΦ⁻¹ = (ΦΦᵀ)⁻¹
    for name, ref in (("G", G_ref), ("C", C_ref)):
        six = data[f"/series/{name}"].components[SCALARS]
        assert six.shape == (N, len(TENSOR_ENTRIES)) and six.dtype == np.float64
        np.testing.assert_allclose(six, symmetric_entries(ref), atol=1e-5, rtol=1e-5, err_msg=name)
    # G is not C's transform of D: they differ unless R = U (sanity: the test is not vacuous)
    assert np.abs(G_ref[-1] - np.linalg.inv(C_ref[-1])).max() > 1e-2
    # eigenvalues: λ², μ², ϱ² for G and their inverses for C (eq. (35))
    G = symmetric_from_entries(data["/series/G"].components[SCALARS])
    np.testing.assert_allclose(np.linalg.eigvalsh(G), np.sort(np.stack([lam, mu, rho], 1) ** 2, axis=1), rtol=1e-12)


def test_transform_and_principal_axes(recorded):
    _, data = recorded
    lam, mu, rho = (series(data, k) for k in ("lambda", "mu", "rho"))
    half = np.stack([lam, mu, rho], axis=1)
    G = data["/series/G"].components[SCALARS]
    C = data["/series/C"].components[SCALARS]
    # Transform3D(mat3x3=Φ) is stored column-major float32
    Phi = (
        data["/world/material"]
        .components["Transform3D:mat3x3"][:, 0, :]
        .reshape(-1, 3, 3)
        .transpose(0, 2, 1)
        .astype(np.float64)
    )
    np.testing.assert_allclose(symmetric_entries(np.swapaxes(Phi, 1, 2) @ Phi), G, atol=2e-5, rtol=2e-5)
    # arrows: eigenvectors of C (spatial) and G (material) whose length is the semi-axis, and whose
    # label prints that same length ("λ = 1.203")
    for ent, six, power in (("/world/axes_C", C, -2), ("/material/axes_G", G, 2)):
        v = data[ent].components["Arrows3D:vectors"].astype(np.float64)  # (N, 3, 3): row i = axis i
        assert v.shape == (N, 3, 3)
        length = np.linalg.norm(v, axis=2)
        np.testing.assert_allclose(length, half, rtol=1e-6)
        if ent == "/world/axes_C":  # labels are points just beyond the tips: λ, μ in the plate, ϱ apart
            lab_ents = ("/world/labels/in_plane", "/world/labels/normal")
        else:
            lab_ents = ("/material/labels",)
        labels = [sum((list(data[e].components["Points3D:labels"][k]) for e in lab_ents), []) for k in range(N)]
        pos = np.concatenate(
            [data[e].components["Points3D:positions"].reshape(N, -1, 3) for e in lab_ents], axis=1
        ).astype(np.float64)
        assert [lab.split(" = ")[0] for lab in labels[0]] == ["λ", "μ", "ϱ"]
        printed = np.array([[float(lab.split(" = ")[1]) for lab in row] for row in labels])
        np.testing.assert_allclose(printed, length, atol=5e-4 + 1e-6)
        # each label's box lies on its arrow's line, beyond its tip: rerun hangs the box under its point, so an
        # in-plane label's point sits LABEL_DROP above the box's centre (the top view's +y)
        extent = float(np.max(half))  # the recorder's extent for a free scene: the largest semi-axis of the run
        pos = pos.copy()
        pos[:, :2, 1] -= LABEL_DROP * extent
        along = np.einsum("nki,nki->nk", pos, v) / length
        np.testing.assert_allclose(np.linalg.norm(pos, axis=2), along, rtol=1e-5)
        assert np.all(along > length)
        M = symmetric_from_entries(six)
        Mv = np.einsum("nij,nkj->nki", M, v)
        np.testing.assert_allclose(Mv, v * (half**power)[:, :, None], atol=1e-5)
    # C's axes are R's columns, G's are U's: different frames once θ ≠ 0 and R ≠ 1
    vc = data["/world/axes_C"].components["Arrows3D:vectors"][-1]
    vg = data["/material/axes_G"].components["Arrows3D:vectors"][-1]
    assert np.abs(vc - vg).max() > 0.1


def test_bad_input_is_a_clear_value_error(traj, scene, tmp_path):
    t, Y, R = traj.t, traj.y, traj.rotation
    ok = tmp_path / "x.rrd"
    with pytest.raises(ValueError, match="states: expected shape"):
        record_arrays(t, Y[:, :-1], R, scene.body, ok, energy=traj.energy)
    bad = Y.copy()
    bad[9, 3] = -0.1
    with pytest.raises(ValueError, match="states: must have rho > 0"):
        record_arrays(t, bad, R, scene.body, ok, energy=traj.energy)
    bad = Y.copy()
    bad[7, 5] = np.nan
    with pytest.raises(ValueError, match="states: must be finite"):
        record_arrays(t, bad, R, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="rotations: must be rotation matrices"):
        record_arrays(t, Y, R * 1.1, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="t: must be non-decreasing"):
        record_arrays(t[::-1], Y, R, scene.body, ok, energy=traj.energy)
    with pytest.raises(ValueError, match="path: .*\\.rrd"):
        record_arrays(t, Y, R, scene.body, tmp_path / "x.txt", energy=traj.energy)
    with pytest.raises(ValueError, match="tensor_every"):
        record_arrays(t, Y, R, scene.body, ok, energy=traj.energy, tensor_every=0)
    no_rot = simulate(scene, t_end=0.5)
    with pytest.raises(ValueError, match="traj.rotation"):
        record_trajectory(no_rot, scene.body, ok)


def test_record_arrays_step_timeline_and_default_energy(traj, scene, tmp_path):
    n = 40
    t, Y, R = traj.t[:n], traj.y[:, :n], traj.rotation[:n]
    path = record_arrays(t, Y, R, scene.body, tmp_path / "arr.rrd", step=np.arange(100, 100 + n))
    data = read_recording(path)
    np.testing.assert_array_equal(data["/world/body"].step, np.arange(100, 100 + n))
    # energy computed by the recorder (eq. (41)) equals the trajectory's
    np.testing.assert_allclose(series(data, "energy"), traj.energy[:n], rtol=1e-12)
    # episodes go through the env recorder only: the one-call writer takes no episode columns
    with pytest.raises(TypeError):
        record_arrays(t, Y, R, scene.body, tmp_path / "x.rrd", actions=np.zeros((n, 4)))


def test_rerun_off_is_an_error_not_a_missing_file(tmp_path, monkeypatch, traj, scene):
    monkeypatch.setenv("RERUN", "off")
    with pytest.raises(ValueError, match="RERUN"):
        record_trajectory(traj, scene.body, tmp_path / "off.rrd")
    assert not (tmp_path / "off.rrd").exists()


def test_importing_the_env_layer_and_cli_does_not_import_rerun():
    code = "import sys, flatbody_env, flatbody_env.recording.wrapper, flatbody_env.recording.writer, flatbody_env.cli.main as c; c.build_parser(); print('rerun' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_s3_and_relative_drift_of_the_conserved_quantities(recorded, traj):
    _, data = recorded
    np.testing.assert_array_equal(series(data, "s3"), traj.state["s3"])  # the body's own s₃
    casimir = traj.state["s1"] ** 2 + traj.state["s2"] ** 2 + traj.state["s3"] ** 2
    for name, q in (("energy", traj.energy), ("casimir", casimir), ("p_theta", traj.state["p_theta"])):
        ref = (q - q[0]) / abs(q[0]) if q[0] != 0 else q - q[0]
        np.testing.assert_allclose(series(data, f"drift/{name}"), ref, rtol=1e-12, atol=1e-15, err_msg=name)
    # an uncontrolled DOP853 run conserves them: the drift plot shows round-off as what it is
    assert np.abs(series(data, "drift/energy")).max() < 1e-6


def test_tensor_numbers_carry_the_entries_and_eigenvalues(recorded):
    _, data = recorded
    e = data["/tensors/numbers"]
    np.testing.assert_array_equal(e.step, np.arange(0, N, 10))  # every tensor_every-th step
    G = symmetric_from_entries(data["/series/G"].components[SCALARS])
    for k in (0, len(e.step) // 2, len(e.step) - 1):
        text = e.components["TextDocument:text"][k][0]
        M = G[e.step[k]]
        rows = [ln for ln in text.splitlines() if "λ²" in ln or "μ²" in ln or "ϱ²" in ln]
        assert len(rows) == 3
        entries = np.array([[float(x) for x in ln.split()[:3]] for ln in rows])
        np.testing.assert_allclose(entries, M, atol=5e-4 + 1e-9)
        eig = sorted(float(ln.split()[-1]) for ln in rows)
        np.testing.assert_allclose(eig, np.linalg.eigvalsh(M), atol=5e-4 + 1e-9)  # eq. (35): λ², μ², ϱ²
        assert f"t = {e.sim_time[k]:.3f}" in text


def test_recordings_use_rerun_public_api_with_one_escape_hatch():
    """No rerun internals (``rerun_bindings``, private methods or attributes) in the recording wing;
    the one piece that depends on rerun's Arrow layout is ``writer._matrix_column``, the only place
    the writer touches pyarrow (its columns are checked value by value in the tests above)."""
    import ast
    import inspect
    import re

    from flatbody_env import recording
    from flatbody_env.recording import geometry, layout, reader, viewer, work, wrapper, writer

    for mod in (recording, geometry, layout, reader, viewer, work, wrapper, writer):
        src = inspect.getsource(mod)
        for private in ("rerun_bindings", "_log_to_stream", "_ARROW_DATATYPE", "to_native"):
            assert private not in src, (mod.__name__, private)
        assert not re.search(r"\brrb?\._[A-Za-z]", src), mod.__name__  # rr._private (rr.__version__ is public)
    tree = ast.parse(inspect.getsource(writer))
    users = {
        fn.name
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef)
        for node in ast.walk(fn)
        if isinstance(node, ast.Import) and any(a.name == "pyarrow" for a in node.names)
    }
    assert users == {"_matrix_column"}
