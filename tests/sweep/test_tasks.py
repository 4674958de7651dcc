"""Plans (keys, coverage), task purity, error records, and the scaling model's closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flatbody_env.bench.sweep import break_even_grid, makespan, model_time
from flatbody_env.sweep.tasks import Task, default_chunk, execute, parse_seeds, plan, seed_of

BODY = {"params": {"J": 1.0, "J3": 1.0}, "potential": {"name": "V3", "kappa": 1.0}, "thickness": {"a": 1.0, "b": 1.0}}


def _map_spec(grid, chunk):
    return {
        "kind": "stability-map",
        "body": BODY,
        "lam_range": [1.02, 3.0],
        "mu_range": [0.3, 3.0],
        "grid": grid,
        "chunk": chunk,
    }


@pytest.mark.parametrize("grid,chunk", [(7, 1), (30, 4), (33, 32), (1000, default_chunk(1000))])
def test_stability_map_plan_covers_every_row_once_in_key_order(grid, chunk):
    tasks = plan(_map_spec(grid, chunk), "out")
    rows = [i for t in tasks for i in range(*t.params["rows"])]
    assert rows == list(range(grid))
    assert [t.key for t in tasks] == sorted(t.key for t in tasks)
    assert len({t.key for t in tasks}) == len(tasks) == math.ceil(grid / chunk)


def test_default_chunk_holds_about_512_points_and_at_least_one_row():
    for grid in (4, 22, 23, 30, 100, 512, 20_000):
        chunk = default_chunk(grid)
        assert 1 <= chunk <= grid
        points = chunk * grid
        assert points >= 512 or chunk == grid  # enough work per task, or the whole grid in one task
        assert chunk == 1 or (chunk - 1) * grid < 512  # no more rows than needed


def test_task_is_a_pure_function_of_its_key():
    task = plan(_map_spec(12, 3), "out")[1]
    a, b = execute(task), execute(Task(kind=task.kind, key=task.key, params=dict(task.params)))
    assert a.error is None and a.payload == b.payload and len(a.payload) > 0
    lam = np.linspace(1.02, 3.0, 12)[3:6]
    assert {r["lambda"] for r in a.payload} <= set(lam.tolist())


def test_failing_task_becomes_an_error_record():
    bad = Task(
        kind="stability-map",
        key="lam-000000-000001",
        params={**plan(_map_spec(8, 1), "out")[0].params, "body": {**BODY, "potential": {"name": "V3", "kappa": -1.0}}},
    )
    out = execute(bad)
    assert out.payload is None and out.error.startswith("ValueError: ") and "kappa" in out.error


def test_seeds_come_from_keys():
    spec = {
        "kind": "seeds",
        "algo": "ppo",
        "seeds": [0, 3, 12],
        "n_timesteps": 10,
        "n_envs": 1,
        "overrides": [],
        "hyperparams_file": None,
        "episodes": 1,
        "eval_seed": 10_000,
    }
    tasks = plan(spec, "out")
    assert [seed_of(t.key) for t in tasks] == [0, 3, 12]
    assert "seed" not in tasks[0].params
    with pytest.raises(ValueError, match="seed-NNNNNN"):
        seed_of("lam-000000-000001")


@pytest.mark.parametrize("text,expected", [("0-7", list(range(8))), ("0,3,5", [0, 3, 5]), ("4-5,1,5", [1, 4, 5])])
def test_parse_seeds(text, expected):
    assert parse_seeds(text) == expected


@pytest.mark.parametrize("text", ["7-0", "a", "-1", "0-20000"])
def test_parse_seeds_rejects(text):
    with pytest.raises(ValueError, match="seeds"):
        parse_seeds(text)


def test_timing_studies_stay_serial():
    with pytest.raises(ValueError, match="stays serial"):
        plan({"kind": "work-precision"}, "out")


def test_makespan_closed_forms():
    assert makespan([1.0] * 10, 3) == 4.0  # ceil(10/3) rounds of equal tasks
    assert makespan([1.0] * 10, 128) == 1.0
    assert makespan([5.0, 1.0, 1.0, 1.0], 2) == 5.0  # the long task bounds it
    assert makespan([1.0, 1.0, 1.0, 5.0], 2) == 6.0  # submitted last, it starts after a short one
    assert model_time([2.0] * 4, 2, t0=0.5, overhead=0.1) == pytest.approx(0.5 + 0.4 + 4.0)


def test_break_even_root_solves_the_cost_balance():
    c, w, t0, o, r = 2e-3, 8, 1.5, 0.01, 4
    g = break_even_grid(c, w, t0=t0, overhead=o, rows_per_task=r)
    assert c * g * g * (1 - 1 / w) == pytest.approx(t0 + g / r * o)
    assert break_even_grid(c, 1, t0=t0, overhead=o, rows_per_task=r) == math.inf
