"""What a recording tells at first sight, read back from the files: the episode's outcome first in the description
and after its name, the distance (the criterion) in front, a reward view not flattened by a constant term, the energy
balance with its residual drawn, the size of a free scene's drift in its title, the time axis in model time (never
minutes), colours apart from the variables', labels clear of their arrows."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import recording_oracles as oracles
from flatbody_env.env.rendering import COLORS
from flatbody_env.recording.layout import (
    SERIES_COLORS,
    TENSOR_ENTRY_COLORS,
    TIME_MARGIN,
    base_title,
    time_unit,
)
from flatbody_env.recording.reader import read_blueprint, read_recording
from flatbody_env.recording.writer import LABEL_CHAR, LABEL_DROP, LABEL_HALF_HEIGHT, record_trajectory

strict_rerun = oracles.strict_rerun
scene = oracles.scene

SCALARS = "Scalars:scalars"


def _record_env(path, env_id: str, *, seed: int, policy: str):
    from flatbody_env.recording.wrapper import RerunRecorder

    env = RerunRecorder(gym.make(env_id, track_rotation=True), path)
    env.action_space.seed(seed)
    env.reset(seed=seed)
    done = False
    while not done:
        a = np.zeros(env.action_space.shape) if policy == "zero" else env.action_space.sample()
        _, _, term, trunc, _ = env.step(a)
        done = term or trunc
    env.close()
    return env.outcomes[0]


def _description(data) -> str:
    text = data.static["/description"]["TextDocument:text"]
    return text[0][0] if isinstance(text, list) else str(text)


def _name(data) -> str:
    return data.static["/__properties"]["RecordingInfo:name"][0][0]


@pytest.fixture(scope="module")
def torque(tmp_path_factory):
    """A failing FlatBodyTorque-v1 episode (seeded random torques never reach the target)."""
    path = tmp_path_factory.mktemp("torque") / "torque.rrd"
    outcome = _record_env(path, "FlatBodyTorque-v1", seed=3, policy="random")
    return path, read_recording(path), read_blueprint(path), outcome


@pytest.fixture(scope="module")
def hold(tmp_path_factory):
    """A FlatBodyHoldUnstable-v1 episode without control: the body drifts off the unstable ellipse and the episode
    ends when it leaves the tolerance."""
    path = tmp_path_factory.mktemp("hold") / "hold.rrd"
    outcome = _record_env(path, "FlatBodyHoldUnstable-v1", seed=1, policy="zero")
    return path, read_recording(path), read_blueprint(path), outcome


def test_a_failing_episode_says_so_first(torque):
    path, data, bp, outcome = torque
    assert outcome.startswith("MISSED") and "never within the tolerance 0.05" in outcome, outcome
    text = _description(data)
    assert text.splitlines()[2] == f"**{outcome}**"  # under the title, before anything else
    assert _name(data).endswith("— MISSED")
    # on screen at first open: the distance (the task's criterion) and the energy balance, not the reward or a tab
    front = [base_title(n) for n in bp.front]
    assert "distance, tolerance" in front and "energy balance H − H₀ = W" in front, front
    assert "residual H − H₀ − W" in front, front  # under the balance, on screen with it
    assert not any(n.startswith(("reward", "actions")) for n in front), front
    d = np.asarray(data["/series/distance"].components[SCALARS], dtype=float).ravel()
    tol = np.asarray(data["/series/distance_tolerance"].components[SCALARS], dtype=float).ravel()
    assert d.min() > tol.max()  # what the outcome says is what the plot shows


def test_an_episode_that_ends_early_says_when_and_why(hold):
    path, data, bp, outcome = hold
    assert outcome.startswith("MISSED") and "ended early" in outcome and "left the target's tolerance" in outcome
    assert _name(data).endswith("— MISSED, ended early")
    events = data["/events"].components["TextLog:text"]
    assert any("left the target's tolerance" in str(e) for e in events), events  # env.core.end_reason's words


def test_the_reward_view_leaves_out_a_constant_term_and_names_it(torque):
    """A failing episode never earns `success`: a term constant over the episode would set the view's scale (the
    v0 HoldUnstable's `alive` ≡ 1 flattened every other term); it is named in the title instead of drawn."""
    _, data, bp, _ = torque
    success = np.asarray(data["/series/reward/success"].components[SCALARS], dtype=float).ravel()
    assert np.ptp(success) == 0
    view = next(v for v in bp.views if v.name.startswith("reward terms"))
    assert "not drawn: success ≡ 0" in view.name
    assert not view.shows("/series/reward/success") and view.shows("/series/reward/proximity")
    lo, hi = np.asarray(view.properties["ScalarAxis:range"], dtype=float).ravel()
    prox = np.asarray(data["/series/reward/proximity"].components[SCALARS], dtype=float).ravel()
    assert np.ptp(prox) >= 0.3 * (hi - lo)  # the term that moves fills the view


def test_the_energy_balance_draws_both_sides_and_its_residual(torque):
    _, data, bp, _ = torque
    dH = np.asarray(data["/series/balance/delta_energy"].components[SCALARS], dtype=float).ravel()
    W = np.asarray(data["/series/balance/work"].components[SCALARS], dtype=float).ravel()
    res = np.asarray(data["/series/residual"].components[SCALARS], dtype=float).ravel()
    np.testing.assert_allclose(res, dH - W, atol=1e-15)
    # H − H₀ wide in H's colour, W thin and light inside it: both seen where they coincide
    wide = data.static["/series/balance/delta_energy"]
    thin = data.static["/series/balance/work"]
    assert float(np.ravel(wide["SeriesLines:widths"])[0]) >= 3 * float(np.ravel(thin["SeriesLines:widths"])[0])
    view = next(v for v in bp.views if v.name.startswith("residual H − H₀ − W"))
    assert f"largest {np.abs(res).max():.2g}" in view.name, view.name
    lo, hi = np.asarray(view.properties["ScalarAxis:range"], dtype=float).ravel()
    assert np.ptp(res) >= 0.3 * (hi - lo) and hi - lo < 1e-3  # drawn at its own size, not flat on the H scale


def test_a_free_scene_gives_the_size_of_its_drift(scene, tmp_path):
    from flatbody_env import simulate

    traj = simulate(scene, t_end=200.0, times=np.linspace(0.0, 200.0, 401), with_rotation=True)
    path = record_trajectory(traj, scene.body, tmp_path / "long.rrd")
    data, bp = read_recording(path), read_blueprint(path)
    drift = next(v for v in bp.views if v.name.startswith("conserved: drift"))
    dh = np.abs(np.asarray(data["/series/drift/energy"].components[SCALARS], dtype=float)).max()
    assert f"largest: H {dh:.2g}" in drift.name, drift.name
    # 200 model time units: logged in milliseconds, so rerun prints +50ms … +200ms, never +1m +2m +3m
    assert time_unit(200.0) == (1e-3, "ms") and time_unit(20.0) == (1.0, "s")
    assert data["/series/lambda"].sim_time[-1] == pytest.approx(200.0)  # read back in model time
    window = next(v for v in bp.views if v.view_class == "TimeSeries").properties["TimeAxis:view_range"]
    assert window["end"] == pytest.approx(200.0 * (1 + TIME_MARGIN) * 1e6, rel=1e-9)  # ns: 214 ms
    assert "+150ms is t = 150" in _description(data)


def _lab(rgb):
    from test_layout import _lab as lab

    return lab(rgb)


def test_series_colours_keep_away_from_the_variables_and_from_each_other():
    """Actions are no pale tint of λ, μ, ϱ or p_θ; the control power is no θ; the reward terms and the G/C entries
    are told apart on black (ΔE in CIELAB)."""
    variables = {
        k: COLORS[k]
        for k in ("lambda", "mu", "rho", "theta", "s3", "p_theta", "energy", "casimir", "distance", "target")
    }
    ours = {k: v for k, v in SERIES_COLORS.items() if k != "balance/delta_energy"}
    ours.update(
        {
            f"G{ij}": tuple(int(c) for c in TENSOR_ENTRY_COLORS[i])
            for i, ij in enumerate(("11", "22", "33", "12", "13", "23"))
        }
    )
    for name, rgb in ours.items():
        for var, vrgb in variables.items():
            assert np.linalg.norm(_lab(rgb) - _lab(vrgb)) >= 25, (name, var)
    names = sorted(ours)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if {ours[a], ours[b]} == {tuple(ours[a])}:
                continue  # an entry of G and the spare colour of the same hue never share a recording's view
            assert np.linalg.norm(_lab(ours[a]) - _lab(ours[b])) >= 20, (a, b)


def test_arrow_labels_sit_clear_of_their_arrows(torque):
    """Seen down the lab's z axis a label's box — its characters' width and its height, hung under its point as rerun
    draws it (the writer's sizes, measured in the viewer at 1600 × 1000) — holds no point of its arrow."""
    _, data, bp, _ = torque
    arrows = np.asarray(data["/world/axes_C"].components["Arrows3D:vectors"], dtype=float)
    pts = np.asarray(data["/world/labels/in_plane"].components["Points3D:positions"], dtype=float)
    labels = data["/world/labels/in_plane"].components["Points3D:labels"]
    top = bp.view("plate, top view (lab +z)")  # its eye is 2.6 × the recording's extent above the plate
    extent = float(np.asarray(top.properties["EyeControls3D:position"], dtype=float).ravel()[2]) / 2.6
    n = min(arrows.shape[0], pts.shape[0])
    checked = 0
    for k in range(0, n, 7):
        for j in range(2):
            tip = arrows[k, j, :2]
            c = pts[k, j, :2] - np.array([0.0, LABEL_DROP * extent])  # the box's centre, under the point
            text = labels[k][j] if isinstance(labels[k], (list, np.ndarray)) else labels[2 * k + j]
            half = np.array([0.5 * len(str(text)) * LABEL_CHAR, LABEL_HALF_HEIGHT]) * extent
            for s in np.linspace(0.0, 1.0, 11):  # the arrow from the centre to its tip
                p = s * tip
                assert not np.all(np.abs(p - c) < half), (k, j, text)
            checked += 1
    assert checked > 50
