"""The task's targets are stable stationary ellipses: the environment's cheap criterion
(flatbody_env.physics.equilibria: q < 0 and a positive-definite shape Hessian, NOTES §7) against the
analysis service's full reduced-Jacobian classification."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.stability import stability_of_shape
from flatbody_env.physics.body import default_body
from flatbody_env.physics.equations import rhs
from flatbody_env.physics.equilibria import stationary_from_shape
from flatbody_env.physics.state import pack
from flatbody_env.env.task import ReachStationaryEllipse


def _match(results, target):
    for r in results:
        if abs(r.ellipse.state["s3"] - target.s3) < 1e-8 and abs(r.ellipse.state["p_theta"] - target.p_theta) < 1e-8:
            return r
    raise AssertionError(f"analysis found no ellipse with s3={target.s3}, p_theta={target.p_theta}")


def test_sampled_targets_are_stationary_and_stable_per_analysis():
    body = default_body()
    task = ReachStationaryEllipse()
    rng = np.random.default_rng(0)
    for _ in range(25):
        target = task.sample_target(rng, body)
        assert np.max(np.abs(rhs(0.0, pack(target.state), None, body)[:10])) < 1e-12  # stationary (θ̇ aside)
        result = _match(stability_of_shape(body, target.lam, target.mu, include_reversed=True), target)
        assert result.classification == "elliptic"


@pytest.mark.parametrize("lam, mu", [(1.6, 0.8), (2.0, 0.6), (1.8, 0.7), (1.3, 1.0), (1.25, 0.85)])
def test_cheap_criterion_agrees_with_full_analysis(lam, mu):
    body = default_body()
    for branch in ("rotation", "circulation"):
        cheap = stationary_from_shape(body, lam, mu, branch=branch)
        full = _match(stability_of_shape(body, lam, mu, include_reversed=True), cheap)
        assert cheap.stable == (full.classification == "elliptic"), (lam, mu, branch, cheap.q, full.classification)
        assert full.out_of_plane_q == pytest.approx(cheap.q, rel=1e-6, abs=1e-9)
