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
