"""Families of stationary ellipses: continuation, folds, stability changes, CSV and chart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env import Body, CustomPotential, Inertia, ThicknessPotential, default_body
from analysis.families import body_with, follow_family, read_family_csv, write_family_csv
from analysis.plots import plot_family
from analysis.stability import analyse_stability
from analysis.stationary import SearchBox, stationary_ellipses

# a potential whose ∂V/∂u has a bump, so that σ₊² = 2J u³ ∂V/∂u is not monotone in u: folds in s3
A, W, K = 0.5, 0.2, 1.0


def _vu(u):
    return K * u / 2 + A * (u - 2) / W**2 * math.exp(-((u - 2) ** 2) / (2 * W * W))


def _value(l, m, r):
    u, v = l + m, l - m
    return K / 4 * (u * u + v * v) - A * math.exp(-((u - 2) ** 2) / (2 * W * W))


def _gradient(l, m, r):
    u, v = l + m, l - m
    a, b = _vu(u), K * v / 2
    return (a + b, a - b, 0.0)


@pytest.mark.parametrize("p_theta, n_folds", [(0.5, 2), (3.0, 2)])
def test_folds_found_where_sigma_plus_squared_is_extremal(p_theta, n_folds):
    body = Body(
        inertia=Inertia.isotropic(1.0, 1.0),
        potential=CustomPotential(value=_value, gradient=_gradient),
        thickness=ThicknessPotential(a=1.0, b=1.0),
    )
    box = SearchBox(lam=(0.3, 4.0), mu=(0.01, 3.0), rho=(0.5, 2.0), n=61, n_rho=8)
    fam = follow_family(body, "s3", 1.0, 8.0, p_theta=p_theta, box=box, seeds=6)
    # independent prediction: folds at the local extrema of φ(u) = 2J u³ V_u(u) (φ = σ₊²), s3 = √φ − p_θ,
    # inside the domain μ > 0, i.e. u > v with v⁴ = σ₋²/(kJ) (V_v = k v / 2)
    u = np.linspace(1.0, 3.5, 400001)
    phi = 2 * u**3 * np.array([_vu(x) for x in u])
    d = np.diff(phi)
    predicted = []
    for i in np.nonzero(d[:-1] * d[1:] < 0)[0] + 1:
        if phi[i] <= 0:
            continue
        s3 = math.sqrt(phi[i]) - p_theta
        v = abs(s3 - p_theta) ** 0.5 / K**0.25
        if 1.0 < s3 < 8.0 and u[i] > v:
            predicted.append(s3)
    predicted.sort()
    found = sorted(e.param for e in fam.folds)
    assert len(predicted) == n_folds
    assert len(found) == len(predicted)
    for f, p in zip(found, predicted):
        assert f == pytest.approx(p, abs=1e-6)
    for br in fam.branches:
        assert all(p.residual <= 1e-10 for p in br)


def test_v3_s3_family_stability_change_matches_direct_analysis():
    body = default_body()
    fam = follow_family(body, "s3", 0.6, 2.5, p_theta=0.5)
    assert len(fam.branches) == 1 and not fam.folds
    changes = [e for e in fam.events if e.kind == "stability-change"]
    assert len(changes) == 1 and changes[0].detail == "elliptic -> hyperbolic"
    s_c = changes[0].param
    before = analyse_stability(body, stationary_ellipses(body, s_c - 0.03, 0.5)[0])
    after = analyse_stability(body, stationary_ellipses(body, s_c + 0.03, 0.5)[0])
    assert before.classification == "elliptic" and after.classification == "hyperbolic"
    # the instability is the out-of-plane one of NOTES §7: q changes sign there
    assert before.out_of_plane_q < 0 < after.out_of_plane_q
    # continuation points agree with the direct solver
    for p in fam.branches[0][::10]:
        direct = stationary_ellipses(body, p.param, 0.5)[0]
        assert direct.lam == pytest.approx(p.lam, abs=1e-9) and direct.mu == pytest.approx(p.mu, abs=1e-9)


def test_constant_family_csv_round_trip_and_chart(tmp_path):
    body = default_body()
    fam = follow_family(body, "kappa", 0.5, 2.0, s3=2.0, p_theta=0.5, seeds=3)
    assert fam.branches and all(p.residual <= 1e-10 for p in fam.branches[0])
    path = write_family_csv(fam, tmp_path / "f.csv")
    rows = read_family_csv(path)
    pts = [r for r in rows if not r["event"]]
    assert len(pts) == sum(len(b) for b in fam.branches)
    assert pts[0]["param"] == fam.branches[0][0].param and pts[0]["classification"] == fam.branches[0][0].classification
    png = plot_family(path, tmp_path / "f.png")
    assert png.stat().st_size > 10_000


def test_bad_family_arguments():
    body = default_body()
    with pytest.raises(ValueError, match="param"):
        follow_family(body, "k", 0.5, 1.0)
    with pytest.raises(ValueError, match="stop"):
        follow_family(body, "s3", 2.0, 1.0)
    with pytest.raises(ValueError, match="start"):
        follow_family(body, "kappa", -1.0, 1.0)
    with pytest.raises(ValueError, match="param"):
        body_with(body, "c", 1.0)


@pytest.mark.parametrize(
    "param, start, stop",
    [("J", 1e-6, 1e6), ("kappa", 1e-6, 1e-3), ("s3", -1e6, 1e6), ("p_theta", 0.05, 4.0)],
)
def test_a_family_never_evaluates_outside_the_requested_range(param, start, stop):
    """The continuation may step past the range only in its arithmetic: every parameter value the equations are
    evaluated at (difference quotients and Newton iterates included) lies in [start, stop], so a range whose ends
    are a constant's allowed bounds (J from 1e-6 to 1e6) is followed, never refused at 9.9e-07."""
    problems: list = []
    fam = follow_family(default_body(), param, start, stop, _problem=problems)
    calls = problems[0].calls
    assert calls, "the equations were never evaluated"
    assert min(calls) >= start and max(calls) <= stop, (min(calls), max(calls))
    for branch in fam.branches:
        assert all(start <= p.param <= stop for p in branch)
    # where and why every branch stops is said: two ends per branch, each a known reason in words
    assert len(fam.ends) == 2 * len(fam.branches)
    assert all(e.reason in ("range", "box", "circle", "no-solution", "points") and e.detail for e in fam.ends)


def test_a_family_over_decades_is_followed_in_ln_p_and_says_where_its_branches_end():
    body = default_body()
    fam = follow_family(body, "J", 1e-6, 1e6)
    assert fam.scale == "log"
    (branch,) = fam.branches
    params = np.array([p.param for p in branch])
    assert params[0] == 1e-6 and params[-1] == 1e6  # both ends of the range, reached exactly
    # every decade gets points, not one linear step of 1.7e4 over J < 1e4
    decades = np.floor(np.log10(params[:-1]))
    assert set(range(-6, 6)) <= set(decades.astype(int).tolist())
    assert [e.reason for e in fam.ends] == ["range", "range"]
    # a spin over ±1e6: both branches are found (seeds spread over the decades) and each end is explained
    fam = follow_family(body, "s3", -1e6, 1e6)
    assert fam.scale == "asinh" and len(fam.branches) == 2
    reasons = sorted(e.reason for e in fam.ends)
    assert reasons == ["box", "box", "circle", "circle"], fam.ends
    box_end = next(e for e in fam.ends if e.reason == "box")
    assert "λ would exceed 50" in box_end.detail and abs(box_end.param) > 1000
    assert fam.empty_seeds == (-1e6, 1e6)


def test_a_family_range_is_refused_in_the_callers_words():
    body = default_body()
    with pytest.raises(ValueError, match=r"^start: must lie in .*1e-06.*got 9\.9e-07"):
        follow_family(body, "J", 9.9e-7, 1.0)
    from analysis.families import check_range

    with pytest.raises(ValueError, match=r"^from: must lie in"):
        check_range("J", 1e-7, 1.0, names=("from", "to"))
    with pytest.raises(ValueError, match=r"^--to: must be greater than --from \(4\), got 0\.05"):
        check_range("s3", 4.0, 0.05, names=("--from", "--to"))
    with pytest.raises(ValueError, match=r"^to: must be greater than from \(4\), got 0\.05"):
        check_range("s3", 4.0, 0.05, names=("from", "to"))
    with pytest.raises(ValueError, match=r"^--from: must lie in \[1e-06, 1e\+06\], got 1e-07$"):
        check_range("J", 1e-7, 1.0, names=("--from", "--to"))
    # the body's own check names the constant varied, never params.J1
    with pytest.raises(ValueError, match=r"^J: must lie in"):
        body_with(body, "J", 1e-7)


def test_a_family_with_no_ellipse_in_its_box_is_refused_in_the_requests_terms_before_any_file(tmp_path):
    from flatbody_env.answers import family_run

    box = SearchBox(lam=(5.0, 6.0), mu=(5.0, 6.0))
    csv, png = tmp_path / "f.csv", tmp_path / "f.png"
    with pytest.raises(ValueError) as e:
        family_run(default_body(), "s3", 0.05, 0.1, p_theta=0.5, box=box, out=str(csv), plot=str(png))
    text = str(e.value)
    assert text.startswith("family: no stationary ellipse over s3 from 0.05 to 0.1, p_theta = 0.5:") and "seeds" in text
    assert str(tmp_path) not in text and not csv.exists() and not png.exists()  # no server folder named, no file left
