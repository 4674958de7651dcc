"""The layout, read back from the files: one code path for a free scene, an env episode and the agent
demo; every view the layout promises is there with its entities, everything logged is shown by
some view, colours and names follow one convention."""

from __future__ import annotations

import numpy as np
import pytest

import recording_oracles as oracles
from flatbody_env.env.rendering import COLORS
from flatbody_env.recording.layout import (
    FLAT_NOTE,
    FLAT_RTOL,
    TARGET_SERIES,
    base_title,
    constant_terms,
    series_views,
    view_specs,
)
from flatbody_env.recording.reader import read_blueprint, read_recording

strict_rerun = oracles.strict_rerun
scene = oracles.scene
traj = oracles.traj
recorded = oracles.recorded  # fixtures
record_flatbody_episode = oracles.record_flatbody_episode

NOT_DRAWN = {"/__properties", "/__properties/time", "/world", "/material"}
"""Entities that carry settings, not pictures (recording properties: the name, the time unit; view coordinates)."""


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    path = tmp_path_factory.mktemp("ep") / "episode.rrd"
    record_flatbody_episode(path, seed=5, steps=25, block=10)
    return path


@pytest.fixture(scope="module")
def episode_one_block(tmp_path_factory):
    """A random-action FlatBody-v0 episode sent as one block (the wrapper's default): its blueprint is built from its values."""
    path = tmp_path_factory.mktemp("ep1") / "episode.rrd"
    record_flatbody_episode(path, seed=0, steps=60)
    return path


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo's code path (agents.demo.rollout with a recording) with a cheap stand-in policy."""
    from agents.demo import rollout

    path = tmp_path_factory.mktemp("demo") / "demo.rrd"
    ep = rollout(
        lambda obs: -0.3 * np.tanh(obs[:, :4]),
        seed=7,
        env_kwargs={"max_episode_steps": 30},
        record_to=path,
        title="demo test",
    )
    assert ep["path"] == path and ep["t"].size == 31
    return path


def _constant_terms(data) -> list[str]:
    """The reward terms of a recording that keep one value at every step (the reward view leaves them out)."""
    ranges = {}
    for e, ent in data.entities.items():
        if e.startswith("/series/reward/"):
            v = np.asarray(ent.components["Scalars:scalars"], dtype=float).ravel()
            ranges[e] = (float(v.min()), float(v.max()), 1)
    return sorted(constant_terms(ranges))


def _kinds(recorded, episode, demo):
    return {"free scene": (recorded[0], False), "env episode": (episode, True), "agent demo": (demo, True)}


@pytest.mark.parametrize("kind", ["free scene", "env episode", "agent demo"])
def test_blueprint_names_each_expected_view_and_entity(kind, recorded, episode, demo):
    path, is_episode = _kinds(recorded, episode, demo)[kind]
    bp = read_blueprint(path)
    data = read_recording(path)
    logged = (set(data.entities) | set(data.static)) - NOT_DRAWN
    # every view of the one layout code path, with its class and its entities
    expected = view_specs(episode=is_episode)
    base = {base_title(v.name): v for v in bp.views}
    assert sorted((c, n) for c, n, _ in expected) == sorted((v.view_class, n) for n, v in base.items())
    for _cls, name, paths in expected:
        view = base[name]
        for p in paths:
            assert view.shows(p), (name, p)
            assert any(e == p or e.startswith(p + "/") for e in logged), (
                f"view {name!r} promises {p}, which is not logged"
            )
    # nothing logged is orphaned, but a reward term constant over the episode: named in the reward view's title instead
    orphans = [e for e in sorted(logged) if not any(v.shows(e) for v in bp.views)]
    const = _constant_terms(data)
    assert set(orphans) <= set(const), orphans
    for e in const:
        assert any(f"{e.rsplit('/', 1)[-1]} ≡" in v.name for v in bp.views if v.name.startswith("reward terms")), e
    # the body's own s₃ is logged and shown beside its target
    assert "/series/s3" in data.entities
    if is_episode:
        for name in TARGET_SERIES:
            assert f"/series/target/{name}" in data.entities
        assert "/series/distance" in data.entities and "/world/target" in data.entities
        assert any(e.startswith("/series/reward/") for e in data.entities) and any(
            e.startswith("/series/action/") for e in data.entities
        )
    else:
        assert not any(v.name.startswith(("reward", "actions", "distance")) for v in bp.views)
    # the time panel collapsed, the side panels closed, sim_time first
    assert bp.panels == {"time_panel": "collapsed", "blueprint_panel": "collapsed", "selection_panel": "collapsed"}
    assert bp.timeline == "sim_time"


def test_top_view_looks_down_the_lab_z_axis_and_tensors_have_a_diverging_map(episode):
    bp = read_blueprint(episode)
    top = bp.view("plate, top view (lab +z)")
    pos = np.asarray(top.properties["EyeControls3D:position"], dtype=float).ravel()
    look = np.asarray(top.properties["EyeControls3D:look_target"], dtype=float).ravel()
    up = np.asarray(top.properties["EyeControls3D:eye_up"], dtype=float).ravel()
    d = pos - look
    assert d[2] > 0 and np.hypot(d[0], d[1]) < 1e-9 * d[2]  # straight down
    assert abs(up @ d) < 1e-12  # "up" in the picture lies in the plate's plane
    # the camera is placed for the body: a few body sizes away
    data = read_recording(episode)
    size = data["/world/body"].components["Ellipsoids3D:half_sizes"][0, 0].max()
    assert 1.5 * size < d[2] < 10 * size
    oblique = bp.view("3-D view")
    dp = np.asarray(oblique.properties["EyeControls3D:position"], dtype=float).ravel()
    assert dp[2] > 0.4 * np.linalg.norm(dp)  # above the plate, not grazing it
    # seen from +z the ϱ axis is a point at the centre: its label is shown in the 3-D view only
    assert (
        top.shows("/world/labels/in_plane")
        and not top.shows("/world/labels/normal")
        and oblique.shows("/world/labels/normal")
    )
    # labels sit beyond the arrows' tips, off the plate: never on the spokes or on each other
    arrows = data["/world/axes_C"].components["Arrows3D:vectors"]
    pts = data["/world/labels/in_plane"].components["Points3D:positions"]
    k = min(len(arrows), len(pts))
    assert np.all(np.linalg.norm(pts[:k], axis=-1) > np.linalg.norm(arrows[:k, :2], axis=-1) + 0.1)


def test_one_colour_per_variable_shared_with_its_target_and_greek_names(episode):
    data = read_recording(episode)

    def style(path):
        st = data.static[path]
        color = np.asarray(st["SeriesLines:colors"]).ravel()
        return st["SeriesLines:names"][0][0], int(color[0])

    def rgb(packed):
        return ((packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255)

    for name in TARGET_SERIES:
        label, var = style(f"/series/{name}")
        tlabel, tgt = style(f"/series/target/{name}")
        assert rgb(var) == rgb(tgt) == COLORS[name], name  # the palette shared with the rgb_array frames
        assert tlabel.startswith(label + "*"), (label, tlabel)
    labels = {
        style(p)[0]
        for p in data.static
        if p.startswith("/series/") and "SeriesLines:names" in data.static[p] and p not in ("/series/G", "/series/C")
    }
    assert {"λ", "μ", "ϱ", "θ", "s₃", "p_θ", "H", "|s|²", "τ₁", "τ₂", "τ₃", "f_ϱ"} <= labels
    assert not any(w in lab for lab in labels for w in ("lambda", "rho", "theta", "tau"))
    # within each plot every series has a colour of its own
    groups: dict[str, list[int]] = {}
    for p in data.static:
        if p.startswith(("/series/reward/", "/series/action/", "/series/drift/")):
            groups.setdefault(p.rsplit("/", 1)[0], []).append(rgb(style(p)[1]))
    for g, colors in groups.items():
        assert len(set(colors)) == len(colors), g
    for sym in ("G", "C"):
        c = np.asarray(data.static[f"/series/{sym}"]["SeriesLines:colors"]).ravel()
        assert len(set(c.tolist())) == 6  # six entries, six colours


def _variable(series: str) -> str:
    """The variable a series draws: ``/series/drift/X[0]`` and ``/series/X[0]`` are X; H − H₀ is H."""
    p = series.split("[")[0].replace("/series/drift/", "/series/")
    return "/series/energy" if p == "/series/balance/delta_energy" else p


def _rgb(packed):
    packed = int(packed)
    return ((packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255)


def _lab(rgb):
    c = np.asarray(rgb, dtype=float) / 255.0
    c = np.where(c > 0.04045, ((c + 0.055) / 1.055) ** 2.4, c / 12.92)
    xyz = (
        np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
        @ c
        / np.array([0.9505, 1.0, 1.089])
    )
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


@pytest.mark.parametrize("kind", ["free scene", "env episode", "agent demo"])
def test_no_panel_draws_round_off_titles_match_and_no_two_variables_share_a_colour(
    kind, recorded, episode_one_block, demo
):
    """From the blueprint and the logged data: (1) a time-series view whose values spread by less than
    FLAT_RTOL of their scale has a fixed axis at least 10⁶ × that spread wide, and says "flat" in its
    title; a view that is not flat fits its data; (2) every title names what the view shows; (3) every
    series (a target apart, which shares its variable's colour on purpose) has a colour of its own."""
    path, is_episode = _kinds(recorded, episode_one_block, demo)[kind]
    bp = read_blueprint(path)
    data = read_recording(path)
    titles = {name: (paths, rule) for name, paths, rule in series_views(episode=is_episode)}
    for view in bp.views:
        if view.view_class != "TimeSeries":
            continue
        flat = view.name.endswith(FLAT_NOTE)
        paths, rule = titles[base_title(view.name)]
        left_out = _constant_terms(data)
        values = np.concatenate(
            [
                np.asarray(data[e].components["Scalars:scalars"], dtype=float).ravel()
                for p in paths
                for e in data.entities
                if (e == p or e.startswith(p + "/")) and e not in left_out
            ]
        )
        lo, hi = np.asarray(view.properties["ScalarAxis:range"], dtype=float).ravel()
        spread = np.ptp(values)
        assert lo <= values.min() and values.max() <= hi, view.name  # the axis holds every value
        if flat:
            assert spread <= FLAT_RTOL * max(np.abs(values).max(), 1.0) * 1e3 and (hi - lo) >= 1e6 * spread, view.name
        else:  # drawn as signal: the spread fills a visible part of the axis
            assert spread >= 0.3 * (hi - lo), view.name
        # the whole run on the time axis, with room right of it for the last tick label
        t_end = max(float(np.max(data[e].sim_time)) for e in data.entities if e.startswith("/series/"))
        window = view.properties["TimeAxis:view_range"]
        assert window["start"] == 0 and 1.03 * t_end * 1e9 <= window["end"] <= 1.1 * t_end * 1e9, (view.name, window)
    # titles name their variables
    for name, (paths, _) in titles.items():
        for p in paths:
            leaf = p.rsplit("/", 1)[-1]
            sym = {
                "lambda": "λ",
                "mu": "μ",
                "rho": "ϱ",
                "s3": "s₃",
                "p_theta": "p_θ",
                "energy": "H",
                "casimir": "|s|²",
                "theta": "θ",
                "G": "G",
                "C": "C",
                "drift": "drift",
                "reward": "reward",
                "distance": "distance",
                "distance_tolerance": "tolerance",
                "action": "actions",
                "balance": "W",
                "power": "power",
                "residual": "residual",
            }[leaf]
            assert sym in name, (name, p)
    if is_episode:
        assert not any("conserved" in v.name for v in bp.views)  # under control nothing is called conserved
        assert any(v.name.startswith("energy balance") for v in bp.views)
    # colours
    colours = {}
    for p, st in data.static.items():
        if p.startswith("/series/") and not p.startswith("/series/target/") and "SeriesLines:colors" in st:
            for i, c in enumerate(np.asarray(st["SeriesLines:colors"]).ravel()):
                colours[f"{p}[{i}]"] = _rgb(c)
    names = sorted(colours)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if {a[:10], b[:10]} == {"/series/G[", "/series/C["} and a[10:] == b[10:]:
                continue  # the same entry of G and C: one colour in both views, by design
            if _variable(a) == _variable(b):
                continue  # a variable and its own drift or change (H and H − H₀): one variable, one colour
            assert np.linalg.norm(_lab(colours[a]) - _lab(colours[b])) >= 19, (a, colours[a], b, colours[b])


def test_the_description_is_on_screen_at_first_open():
    """The description is a view of its own in the top row (the first five views), not a tab."""
    for episode in (False, True):
        top = [name for _, name, _ in view_specs(episode=episode)[:5]]
        assert "description: what each view shows" in top and "G, C: numbers and eigenvalues" in top


def test_numbers_and_labels_are_each_steps_own_formatting():
    """The tensor numbers and arrow labels, formatted for all steps in one call, equal each step
    formatted alone (the per-step f-strings below are the oracle), for awkward values too."""
    from flatbody_env.recording.layout import axis_labels, tensor_text

    rng = np.random.default_rng(1)
    n = 40
    t = np.cumsum(rng.random(n))
    G, C = rng.normal(size=(n, 3, 3)) * 300, rng.normal(size=(n, 3, 3))
    half = rng.random((n, 3)) + 0.2
    G[0, 0, 0], C[1, 1, 1], G[2, 0, 1], C[3, 2, 2], half[4, 1] = np.nan, -np.inf, -0.0, 0.0625, 12345.6785
    for _ in (1,):
        expected = []
        for k in range(n):
            lam, mu, rho = half[k]
            g, c = G[k], C[k]
            expected.append(
                f"**t = {t[k]:.3f}**\n\n```\nG = ΦᵀΦ               eigenvalue\n"
                f"{g[0, 0]:+7.3f}{g[0, 1]:+7.3f}{g[0, 2]:+7.3f}  λ² {lam * lam:.3f}\n"
                f"{g[1, 0]:+7.3f}{g[1, 1]:+7.3f}{g[1, 2]:+7.3f}  μ² {mu * mu:.3f}\n"
                f"{g[2, 0]:+7.3f}{g[2, 1]:+7.3f}{g[2, 2]:+7.3f}  ϱ² {rho * rho:.3f}\n\n"
                "C = Φ⁻ᵀΦ⁻¹            eigenvalue\n"
                f"{c[0, 0]:+7.3f}{c[0, 1]:+7.3f}{c[0, 2]:+7.3f}  λ⁻² {1 / (lam * lam):.3f}\n"
                f"{c[1, 0]:+7.3f}{c[1, 1]:+7.3f}{c[1, 2]:+7.3f}  μ⁻² {1 / (mu * mu):.3f}\n"
                f"{c[2, 0]:+7.3f}{c[2, 1]:+7.3f}{c[2, 2]:+7.3f}  ϱ⁻² {1 / (rho * rho):.3f}\n```\n\n"
                "Green tensor G (material frame) and Cauchy tensor C (laboratory): their entries over time are "
                "the tabs *G entries* and *C entries*."
            )
        assert tensor_text(t, G, C, half) == expected
    assert axis_labels(half) == [f"{s} = {v:.3f}" for row in half for s, v in zip("λμϱ", row)]
    assert tensor_text(t[:0], G[:0], C[:0], half[:0]) == [] and axis_labels(half[:0]) == []


def test_a_demo_that_fails_midway_leaves_no_recording(tmp_path):
    """The demo's recording is written atomically: a policy that fails half-way leaves neither the
    file nor a temporary one; a previous recording under that name stays as it was."""
    from agents.demo import rollout

    calls = {"n": 0}

    def failing(obs):
        calls["n"] += 1
        if calls["n"] > 10:
            raise RuntimeError("policy failed")
        return np.zeros((1, 4))

    path = tmp_path / "demo.rrd"
    with pytest.raises(RuntimeError, match="policy failed"):
        rollout(failing, seed=7, env_kwargs={"max_episode_steps": 30}, record_to=path)
    assert list(tmp_path.iterdir()) == []
    path.write_bytes(b"previous")
    calls["n"] = 0
    with pytest.raises(RuntimeError, match="policy failed"):
        rollout(failing, seed=7, env_kwargs={"max_episode_steps": 30}, record_to=path)
    assert path.read_bytes() == b"previous" and [p.name for p in tmp_path.iterdir()] == ["demo.rrd"]


def _check_series_axes(path, is_episode, *, t_factor):
    """Every time-series view of ``path``'s blueprint holds its values, is flat (and says so) exactly
    when they are round-off, and shows the whole run with room on the right (end in t_end × t_factor)."""
    bp = read_blueprint(path)
    data = read_recording(path)
    titles = {name: (paths, rule) for name, paths, rule in series_views(episode=is_episode)}
    t_end = max(float(np.max(data[e].sim_time)) for e in data.entities if e.startswith("/series/"))
    seen_flat = []
    for view in bp.views:
        if view.view_class != "TimeSeries":
            continue
        flat = view.name.endswith(FLAT_NOTE)
        paths, _ = titles[base_title(view.name)]
        left_out = _constant_terms(data)
        values = np.concatenate(
            [
                np.asarray(data[e].components["Scalars:scalars"], dtype=float).ravel()
                for p in paths
                for e in data.entities
                if (e == p or e.startswith(p + "/")) and e not in left_out
            ]
        )
        values = values[np.isfinite(values)]
        lo, hi = np.asarray(view.properties["ScalarAxis:range"], dtype=float).ravel()
        assert lo <= values.min() and values.max() <= hi, view.name
        spread = np.ptp(values)
        if flat:
            seen_flat.append(view.name)
            assert (hi - lo) >= 1e6 * spread, view.name
        elif view.name.startswith("residual"):  # the balance's check: drawn at its own size, however small
            assert spread >= 0.3 * (hi - lo), view.name
        else:
            assert spread > FLAT_RTOL * max(np.abs(values).max(), 1.0) and spread >= 0.3 * (hi - lo), view.name
        window = view.properties["TimeAxis:view_range"]
        assert window["start"] == 0 and t_factor[0] * t_end * 1e9 <= window["end"] <= t_factor[1] * t_end * 1e9, (
            view.name,
            window,
        )
    return bp, seen_flat


def test_a_recording_of_several_blocks_keeps_the_flat_rule_and_the_whole_run(episode, scene, traj, tmp_path):
    """A recording longer than one block (the wrapper's episodes beyond 1024 steps; a live ``Recorder``
    in blocks) gets, like a one-block recording, a blueprint built from all its values: round-off drawn
    flat with the title saying so, fixed axes holding the data, the whole run on the time axis. The
    file is opened with the first block's blueprint; later blocks send a new one only when the axes
    change, so a 40-block recording holds a few, and the last one (the viewer's) is read back."""
    import rerun.chunk as rrc

    from flatbody_env.recording.writer import Recorder

    _check_series_axes(episode, True, t_factor=(1.03, 1.65))  # 25 steps in blocks of 10
    path = tmp_path / "live.rrd"
    t, y, R = traj.t, traj.y, traj.rotation
    n = 2000
    times = np.linspace(0.0, 4.0 * t[-1], n)  # the scene's trajectory played four times: 2000 steps, 40 blocks of 50
    idx = np.arange(n) % t.size
    with Recorder(path, scene.body, block=50) as rec:
        for k in range(n):
            rec.append(float(times[k]), y[:, idx[k]], R[idx[k]], energy=float(traj.energy[idx[k]]))
    bp, flat = _check_series_axes(path, False, t_factor=(1.03, 1.65))
    assert any(name.startswith("conserved: drift") for name in flat), flat  # H, |s|², p_θ: round-off, drawn flat
    assert any(name.startswith("p_θ") for name in flat), flat
    sent = len(rrc.RrdReader(path).blueprints())
    assert 2 <= sent <= 12, sent
