"""The task's targets are stable stationary ellipses: the environment's cheap criterion
(flatbody_env.physics.equilibria: q < 0 and a positive-definite shape Hessian, NOTES §7) against the
analysis service's full reduced-Jacobian classification."""

from __future__ import annotations

import gymnasium as gym
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


# --- the shipped settling-rate table (flatbody_env.env.targets) ---------------------------------------------------
from flatbody_env.env import targets as target_table  # noqa: E402
from flatbody_env.physics.controllability import settling_rate, target_state  # noqa: E402

LIMITS = np.array([0.5, 0.5, 0.5, 1.0])


def test_table_applies_only_where_it_was_computed():
    table = target_table.shipped_table()
    assert table is not None, "the package ships its settling-rate table"
    body, task = default_body(), ReachStationaryEllipse()
    assert table.applies(body, LIMITS, "torque+dilatation", task.target_lambda, task.target_aspect)
    assert not table.applies(body, LIMITS * 2, "torque+dilatation", task.target_lambda, task.target_aspect)
    assert not table.applies(body, LIMITS, "torque", task.target_lambda, task.target_aspect)
    assert not table.applies(body, LIMITS, "torque+dilatation", (1.2, 2.0), task.target_aspect)
    other = body.to_dict()
    other["params"] = {**other["params"], "J3": 2.0}
    from flatbody_env.physics.body import Body

    assert not table.applies(Body.from_dict(other), LIMITS, "torque+dilatation", task.target_lambda, task.target_aspect)
    mismatch = table.mismatch  # by the keyword that sets each
    assert mismatch(body, LIMITS, "torque+dilatation", task.target_lambda, task.target_aspect) == ()
    assert mismatch(body, LIMITS * [1, 1, 1, 2], "torque", (1.2, 2.0), (1.0, 9.0)) == (
        "control", "force_limit", "target_lambda", "target_aspect",
    )  # fmt: skip
    assert mismatch(Body.from_dict(other), LIMITS * 2, "torque+dilatation", task.target_lambda, task.target_aspect) == (
        "torque_limit", "force_limit", "body",
    )  # fmt: skip


def test_a_v1_task_outside_the_table_is_refused_naming_what_took_it_there():
    """The v1 resets decide reachability by the shipped table: a setting it does not cover is refused at once, by the
    keyword the user changed (and its range where it is a target range), with the way out (no filter)."""
    for kwargs, names in (
        ({"target_lambda": (1.0, 1.0)}, "target_lambda: "),
        ({"torque_limit": 0.3}, "torque_limit: "),
        ({"target_lambda": (1.0, 1.5), "force_limit": 2.0}, "force_limit, target_lambda: "),
    ):
        with pytest.raises(ValueError, match="min_settling_rate=0") as err:
            gym.make("FlatBodySlow-v1", **kwargs)
        assert str(err.value).startswith(names), str(err.value)
    assert "its λ* in [1.3, 2], got (1.0, 1.0)" in str(_refusal(target_lambda=(1.0, 1.0)))
    gym.make("FlatBodySlow-v1", target_lambda=(1.0, 1.0), min_settling_rate=0).close()  # the way out


def _refusal(**kwargs) -> ValueError:
    try:
        gym.make("FlatBodySlow-v1", **kwargs)
    except ValueError as exc:
        return exc
    raise AssertionError(f"accepted {kwargs}")


def test_table_draws_the_same_targets_as_the_exact_test():
    """Same seeds, same targets (bit for bit), so the same distribution: with the table, without it."""
    body = default_body()
    fast, exact = ReachStationaryEllipse(), ReachStationaryEllipse(settling_table=False)
    drawn = []
    for seed in range(40):
        a = fast.sample_target(np.random.default_rng(seed), body)
        b = exact.sample_target(np.random.default_rng(seed), body)
        assert a == b
        drawn.append((a.lam, a.lam / a.mu, np.sign(a.p_theta)))
    lam, aspect, sign = np.array(drawn).T
    # the statistics of the sampled targets: inside the ranges, both signs, the fast shapes near the edge of existence
    assert lam.min() >= 1.3 and lam.max() <= 2.0 and aspect.min() >= 1.5 and aspect.max() <= 3.5
    assert 0 < (sign > 0).mean() < 1
    assert np.all(lam * lam / aspect >= 1.0)  # V3: λ*μ* ≥ 1 where the circulation family exists


def test_table_decisions_agree_with_the_exact_criterion():
    """At random shapes (half of them in cells the threshold crosses) every decided shape passes or fails
    the exact test as the table says, and the sampled targets meet the criterion itself."""
    table = target_table.shipped_table()
    body = default_body()
    rng = np.random.default_rng(1)
    crossing = np.argwhere(table.refined >= 0)
    dl, da = table.lambdas[1] - table.lambdas[0], table.aspects[1] - table.aspects[0]
    decided = 0
    for n in range(120):
        if n % 2:
            j, i = crossing[rng.integers(len(crossing))]
            lam, aspect = table.lambdas[i] + rng.random() * dl, table.aspects[j] + rng.random() * da
        else:
            lam, aspect = rng.uniform(1.3, 2.0), rng.uniform(1.5, 3.5)
        code = table.decide(lam, aspect, 0.15)
        if code == target_table.UNSURE:
            continue
        decided += 1
        r = target_table.exact_rate(body, lam, aspect, LIMITS)
        if code == target_table.REJECT:
            assert not r >= 0.15, (lam, aspect, r)
        elif code == target_table.ACCEPT_IF_STABLE:  # an edge cell: passes wherever a stable ellipse exists
            assert np.isnan(r) or r >= 0.15, (lam, aspect, r)
        else:
            assert r >= 0.15, (lam, aspect, r)
    assert decided >= 110
    task = ReachStationaryEllipse()
    sample_rng = np.random.default_rng(7)
    for _ in range(10):
        t = task.sample_target(sample_rng, body)
        assert settling_rate(body, target_state(t.lam, t.mu, t.rho, t.s3, t.p_theta), LIMITS, np.ones(4, bool)) >= 0.15


def test_table_file_of_another_version_is_refused(tmp_path):
    table = target_table.shipped_table()
    meta = {**table.meta, "version": target_table.TABLE_VERSION + 1}
    from dataclasses import replace

    replace(table, meta=meta).save(tmp_path / "t.npz")
    with pytest.raises(ValueError, match="table"):
        target_table.SettlingRateTable.load(tmp_path / "t.npz")
