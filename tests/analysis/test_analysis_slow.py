"""Long checks of the stationary-ellipse analysis over the default body's shapes (pytest -m slow)."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env import default_body
from analysis.stability import stability_of_shape
from analysis.verification import verify_bounded, verify_growth, verify_stationary


@pytest.mark.slow
def test_default_body_shape_grid_classification_confirmed_by_simulation():
    body = default_body()
    checked = {"hyperbolic": 0, "elliptic": 0}
    for lam in np.linspace(1.1, 2.8, 6):
        for mu in np.linspace(0.45, 2.6, 6):
            if not mu < lam:
                continue
            for r in stability_of_shape(body, float(lam), float(mu)):
                assert verify_stationary(body, r.ellipse, t_end=100.0).max_drift <= 1e-8
                if r.classification == "hyperbolic":
                    g = verify_growth(body, r)
                    assert g.relative_error < 0.10, (lam, mu, g.predicted_rate, g.measured_rate)
                    checked["hyperbolic"] += 1
                elif r.classification == "elliptic":
                    b = verify_bounded(body, r, eps=1e-6, t_end=100.0)
                    assert b.passed, (lam, mu, r.ellipse.kind, b.max_ratio, b.growth_ratio)
                    checked["elliptic"] += 1
    assert checked["hyperbolic"] >= 5 and checked["elliptic"] >= 10
