"""The result store: upsert by key, atomic rows, the sweep's specification checked on resume."""

from __future__ import annotations

import sqlite3

import pytest

from flatbody_env.sweep.store import STORE_NAME, ResultStore

SPEC = {"kind": "stability-map", "grid": 8, "chunk": 2}


def test_upsert_by_key_keeps_one_row_per_key(tmp_path):
    with ResultStore(tmp_path) as store:
        store.begin(SPEC, resume=False)
        store.put("b", payload=[{"x": 1.5}])
        store.put("a", error="ValueError: boom")
        store.put("a", payload=[{"x": float("nan")}, {"x": 0.1 + 0.2}])  # a retried task replaces its error
        res = store.results()
    assert [r.key for r in res] == ["a", "b"]
    assert res[0].status == "ok" and res[0].error is None
    assert res[0].payload[1]["x"] == 0.1 + 0.2  # floats round-trip exactly
    assert res[0].payload[0]["x"] != res[0].payload[0]["x"]  # NaN survives as NaN
    rows = sqlite3.connect(tmp_path / STORE_NAME).execute("SELECT COUNT(*), COUNT(DISTINCT key) FROM rows").fetchone()
    assert rows == (2, 2)


def test_done_keys_skip_errors_unless_asked(tmp_path):
    with ResultStore(tmp_path) as store:
        store.begin(SPEC, resume=False)
        store.put("ok", payload=1)
        store.put("bad", error="RuntimeError: x")
        assert store.done_keys() == {"ok"}
        assert store.done_keys(include_errors=True) == {"ok", "bad"}


def test_resume_rules(tmp_path):
    with ResultStore(tmp_path / "a") as store, pytest.raises(ValueError, match="resume: no sweep"):
        store.begin(SPEC, resume=True)
    with ResultStore(tmp_path / "b") as store:
        store.begin(SPEC, resume=False)
        store.put("k", payload=[])
    with ResultStore(tmp_path / "b") as store:  # reopened: rows and spec persisted
        assert store.spec() == SPEC and store.count() == 1
        with pytest.raises(ValueError, match="already holds a sweep; pass --resume"):
            store.begin(SPEC, resume=False)
        with pytest.raises(ValueError, match=r"other parameters \(grid differ\)"):
            store.begin({**SPEC, "grid": 9}, resume=True)
        store.begin(SPEC, resume=True)


BENCH = {
    "kind": "benchmark",
    "algos": ["ppo", "sac"],
    "envs": ["FlatBody-v1"],
    "seeds": [0, 1],
    "budgets": {"ppo": 5000, "sac": 2000, "td3": 2000},
    "eval_seed": 7,
}


def test_a_benchmark_resumed_with_one_more_algorithm_keeps_its_rows_and_takes_the_new_spec(tmp_path):
    from flatbody_env.sweep.tasks import extends, plan

    with ResultStore(tmp_path) as store:
        store.begin(BENCH, resume=False, extends=extends)
        store.put("ppo.FlatBody-v1.000000", payload={"curve": []})
        more = {**BENCH, "algos": ["ppo", "sac", "td3"], "budgets": {**BENCH["budgets"], "td3": 3000}}
        store.begin(more, resume=True, extends=extends)
        assert store.spec() == more and store.done_keys() == {"ppo.FlatBody-v1.000000"}
        todo = {t.key for t in plan(more, tmp_path)} - store.done_keys()
        assert {k.split(".")[0] for k in todo} == {"ppo", "sac", "td3"} and len(todo) == 5
        # what would change a stored row's meaning is refused: another budget for a stored algorithm, other seeds,
        # another task, an algorithm dropped
        for other in (
            {**more, "budgets": {**more["budgets"], "ppo": 6000}},
            {**more, "seeds": [0, 1, 2]},
            {**more, "envs": ["FlatBodySlow-v1"]},
            {**more, "algos": ["ppo", "td3"]},
        ):
            with pytest.raises(ValueError, match="started with other parameters"):
                store.begin(other, resume=True, extends=extends)
        assert store.spec() == more
    with ResultStore(tmp_path / "map") as store:  # other kinds never extend
        store.begin(SPEC, resume=False, extends=extends)
        with pytest.raises(ValueError, match="grid differ"):
            store.begin({**SPEC, "grid": 16}, resume=True, extends=extends)
