"""The benchmark's report (agents/benchmark.py): learning curves over the training seeds with t-intervals, the final
table of normalised scores and the suite's IQM, the saved files and the docs block — from rows laid out as
``flatbody benchmark`` stores them (the end-to-end run is the slow smoke case of tests/cli/test_smoke.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from agents.benchmark import curves, final_table, markdown, mean_interval, report
from agents.reference import REFERENCE_DIR, load_reports


def _rows(algo: str, envs, seeds, success):
    rows = []
    for env_id in envs:
        for s in seeds:
            final = {"success_rate": success(env_id, s), "return": 10.0 * s, "final_distance": 0.01,
                     "final_distance_median": 0.01}  # fmt: skip
            curve = [
                {"env_steps": 500 * (k + 1), "train_seconds": 2.0 * (k + 1) + s, **final, "success_rate": f * final["success_rate"]}
                for k, f in enumerate((0.0, 0.5, 1.0))
            ]  # fmt: skip
            rows.append({"algo": algo, "env_id": env_id, "seed": s, "budget": 1500, "curve": curve, "final": final,
                         "train_seconds": 6.0 + s, "run": f"runs/{algo}-{env_id}-{s}"})  # fmt: skip
    return rows


def test_mean_interval_is_the_student_t_interval():
    v = [0.2, 0.4, 0.9, 0.5, 0.6]
    m, lo, hi = mean_interval(v)
    a, b = stats.t.interval(0.95, len(v) - 1, loc=np.mean(v), scale=stats.sem(v))
    assert m == pytest.approx(np.mean(v)) and lo == pytest.approx(a) and hi == pytest.approx(b)
    assert mean_interval([0.3]) == (0.3, 0.3, 0.3)


def test_curves_table_files_and_docs_block_come_from_the_rows(tmp_path, monkeypatch):
    refs = [r for r in load_reports(REFERENCE_DIR) if r["env_id"] in ("FlatBody-v1", "FlatBodySlow-v1")]
    envs = [r["env_id"] for r in refs]
    rows = _rows("ppo", envs, range(5), lambda e, s: 0.9 + 0.02 * s) + _rows("sac", envs, range(5), lambda e, s: 0.1)
    c = curves(rows)
    assert set(c) == {f"{a}|{e}" for a in ("ppo", "sac") for e in envs}
    last = c["ppo|FlatBody-v1"]["points"][-1]
    assert last["success"] == pytest.approx(mean_interval([0.9 + 0.02 * s for s in range(5)]))
    assert c["ppo|FlatBody-v1"]["seeds"] == [0, 1, 2, 3, 4]
    table = final_table(rows, refs)
    lo = table["anchors"]["FlatBodySlow-v1"]["lo"]
    hi = table["anchors"]["FlatBodySlow-v1"]["hi"]
    cell = table["cells"]["ppo|FlatBodySlow-v1"]
    assert cell["score_mean"][0] == pytest.approx((np.mean(cell["success"]) - lo) / (hi - lo))
    assert table["iqm"]["ppo"]["iqm"] > table["iqm"]["sac"]["iqm"]  # ranks as the successes do
    assert table["iqm"]["ppo"]["lo"] <= table["iqm"]["ppo"]["iqm"] <= table["iqm"]["ppo"]["hi"]
    paths = report(rows, tmp_path, refs)
    assert {p.name for p in paths.values()} == {"benchmark.json", "benchmark.csv", "benchmark_curves.png",
                                                "benchmark_iqm.png"}  # fmt: skip
    saved = json.loads(paths["json"].read_text())
    assert len(saved["rows"]) == 20 and len(paths["csv"].read_text().splitlines()) == 21
    # run folders below the working directory are saved relative to it (the same on every machine), others as given
    repo = tmp_path / "repo"
    repo.mkdir()
    monkeypatch.chdir(repo)
    inside, outside = repo / "runs" / "x", tmp_path / "elsewhere" / "y"
    report([{**rows[0], "run": str(inside)}, {**rows[1], "run": str(outside)}] + rows[2:], tmp_path / "b", refs)
    runs = [r["run"] for r in json.loads((tmp_path / "b" / "benchmark.json").read_text())["rows"][:2]]
    assert runs == ["runs/x", str(outside)]
    block = markdown(saved, "flatbody benchmark --algos ppo,sac")
    assert "flatbody benchmark --algos ppo,sac" in block and "FlatBodySlow-v1" in block


def test_a_hyperparameter_grid_plans_one_case_per_value_and_reports_its_sensitivity(tmp_path):
    from agents.benchmark import sensitivity
    from flatbody_env.sweep.tasks import extends, plan

    spec = {"kind": "benchmark", "algos": ["ppo"], "envs": ["FlatBody-v1"], "seeds": [0, 1, 2],
            "budgets": {"ppo": 5000}, "eval_seed": 7, "grid": {"key": "learning_rate", "values": ["1e-4", "1e-3", "3e-3"]}}  # fmt: skip
    tasks = plan(spec, tmp_path)
    assert len(tasks) == 9 and len({t.key for t in tasks}) == 9
    assert sorted({tuple(t.params["overrides"]) for t in tasks}) == [
        (f"learning_rate={v}",) for v in ("1e-3", "1e-4", "3e-3")
    ]
    assert not extends(spec, {**spec, "grid": {"key": "learning_rate", "values": ["1e-4"]}})  # another grid: refused
    # rows as run_case writes them for a grid: the label names the value; success peaks at 1e-3
    peak = {"1e-4": 0.2, "1e-3": 0.8, "3e-3": 0.4}
    rows = []
    for value, base in peak.items():
        for r in _rows(f"ppo learning_rate={value}", ["FlatBody-v1"], range(3), lambda e, s, b=base: b + 0.01 * s):
            rows.append({**r, "base_algo": "ppo", "overrides": [f"learning_rate={value}"]})
    sens = sensitivity(rows)
    cell = sens["cells"]["ppo|FlatBody-v1"]
    assert sens["hyperparam"] == "learning_rate" and cell["values"] == [1e-4, 1e-3, 3e-3]
    assert [m for m, _, _ in cell["success"]] == pytest.approx([0.21, 0.81, 0.41]) and cell["seeds"] == [3, 3, 3]
    assert sensitivity(_rows("ppo", ["FlatBody-v1"], range(2), lambda e, s: 0.5)) == {}  # no grid, no chart
    refs = [r for r in load_reports(REFERENCE_DIR) if r["env_id"] == "FlatBody-v1"]
    paths = report(rows, tmp_path, refs)
    assert paths["sensitivity"].name == "benchmark_sensitivity.png" and paths["sensitivity"].stat().st_size > 10_000
    block = markdown(json.loads(paths["json"].read_text()), "flatbody benchmark ...")
    header = block.splitlines()[0]
    assert header.index("learning_rate=1e-4") < header.index("learning_rate=1e-3") < header.index("learning_rate=3e-3")


def test_a_bad_hyperparameter_grid_stops_the_benchmark_before_it_trains(tmp_path, capsys):
    from flatbody_env.cli.main import main

    base = ["benchmark", "--algos", "ppo", "--envs", "FlatBody-v1", "--seeds", "0-1", "--out", str(tmp_path / "b")]
    for grid, words in (
        ("learning_rate=1e-4", "must hold 2 to 16 values"),
        ("learning_rate=1e-4,-1", "hyperparams.learning_rate"),
        ("lr=1e-4,1e-3", "hyperparams.lr: unknown field"),
        ("learning_rate", "expected KEY=V1,V2"),
    ):
        assert main([*base, "--hyperparam-grid", grid]) == 2
        err = capsys.readouterr().err
        assert "--hyperparam-grid" in err and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b").exists()


def test_fixed_hyperparameters_and_the_device_are_planned_named_and_checked_before_anything_trains(tmp_path, capsys):
    """``--hyperparams`` and ``--device`` reach every case, name its key and its label; a stored benchmark resumes only
    with the same ones; bad values, SB3 on CUDA and CUDA without a GPU are one line naming the flag, nothing trained."""
    import torch

    from flatbody_env.cli.main import main
    from flatbody_env.sweep.tasks import extends, plan

    spec = {"kind": "benchmark", "algos": ["rsl-ppo"], "envs": ["FlatBody-v1", "FlatBodySlow-v1"], "seeds": [0, 1],
            "budgets": {"rsl-ppo": 5000}, "eval_seed": 7, "hyperparams": ["n_envs=65536"], "device": "cuda"}  # fmt: skip
    tasks = plan(spec, tmp_path)
    assert len(tasks) == 4 and all(t.key.startswith("rsl-ppo@n_envs=65536@device=cuda.") for t in tasks)
    assert all(t.params["device"] == "cuda" and t.params["hyperparams"] == ["n_envs=65536"] for t in tasks)
    plain = {k: v for k, v in spec.items() if k not in ("hyperparams", "device")}
    assert all("device" not in t.params and "hyperparams" not in t.params for t in plan(plain, tmp_path))
    assert not extends(plain, spec) and not extends(spec, plain) and extends(spec, dict(spec))
    assert not extends(spec, {**spec, "hyperparams": ["n_envs=4096"]})
    base = ["benchmark", "--envs", "FlatBody-v1", "--seeds", "0-1", "--out", str(tmp_path / "b"), "--no-progress"]
    cases = [
        (["--algos", "ppo,rsl-ppo", "--device", "cuda"], "--device: cuda trains rsl-ppo only"),
        (["--algos", "rsl-ppo", "--hyperparams", "n_envs=0"], "hyperparams.n_envs"),
        (["--algos", "rsl-ppo", "--hyperparams", "n_envs"], "expected KEY=VALUE"),
        (["--algos", "ppo", "--hyperparams", "num_steps_per_env=8"], "--hyperparams: ppo on FlatBody-v1"),
    ]
    if not torch.cuda.is_available():
        cases.append((["--algos", "rsl-ppo", "--device", "cuda"], "--device: must be cpu here: no CUDA GPU"))
    for extra, words in cases:
        assert main([*base, *extra]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "b").exists()


def test_a_case_with_fixed_hyperparameters_trains_with_them_and_is_labelled_by_them(tmp_path):
    """A benchmark case (the sweep's task, as ``flatbody benchmark --hyperparams`` plans it) trains with every fixed
    override, is labelled by them, and its ``run.json`` names a command that gives them all."""
    import json

    import yaml

    import agents.benchmark as bm
    from flatbody_env.cli.main import build_parser
    from flatbody_env.sweep.tasks import benchmark_case, plan

    fixed = ["n_envs=8", "num_steps_per_env=8"]
    spec = {"kind": "benchmark", "algos": ["rsl-ppo"], "envs": ["FlatBody-v1"], "seeds": [0, 1],
            "budgets": {"rsl-ppo": 128}, "eval_seed": 10_000, "hyperparams": fixed}  # fmt: skip
    task = plan(spec, tmp_path)[0]
    row = benchmark_case(task)
    assert row["algo"] == "rsl-ppo n_envs=8 num_steps_per_env=8" and row["base_algo"] == "rsl-ppo"
    assert row["hyperparams"] == fixed and "device" not in row and "overrides" not in row
    run = tmp_path / "runs" / task.key
    hp = yaml.safe_load((run / "config.yml").read_text())["hyperparams"]
    assert hp["n_envs"] == 8 and hp["num_steps_per_env"] == 8
    assert row["curve"][-1]["env_steps"] == 128 and row["final"]["episodes"] == bm.FINAL_EPISODES
    command = json.loads((run / "run.json").read_text())["command"]
    args = build_parser().parse_args([*command[command.index("benchmark") :], "--out", str(tmp_path / "again")])
    assert args.hyperparams == fixed


def test_retrain_removes_only_the_named_algorithms_runs_and_only_from_this_benchmark(tmp_path, capsys):
    import argparse

    from flatbody_env.cli.main import main
    from flatbody_env.cli.sweep import _forget_runs
    from flatbody_env.sweep.store import ResultStore
    from flatbody_env.sweep.tasks import plan

    spec = {"kind": "benchmark", "algos": ["ppo", "sac"], "envs": ["FlatBody-v1"], "seeds": [0, 1],
            "budgets": {"ppo": 5000, "sac": 2000, "td3": 30000, "rsl-ppo": 2000000}, "eval_seed": 10000}  # fmt: skip
    out = tmp_path / "b"
    with ResultStore(out) as store:
        store.begin(spec, resume=False)
        for task in plan(spec, out):
            store.put(task.key, payload={"curve": []})
    ns = argparse.Namespace(retrain="ppo", resume=True, out=str(out))
    _forget_runs(spec, ns)
    with ResultStore(out) as store:
        assert store.done_keys() == {"sac.FlatBody-v1.000000", "sac.FlatBody-v1.000001"}
    assert "2 stored runs of ppo removed" in capsys.readouterr().out
    base = ["benchmark", "--algos", "ppo,sac", "--envs", "FlatBody-v1", "--out", str(out), "--no-progress"]
    for extra, words in (
        (["--seeds", "0-1", "--retrain", "sac"], "needs --resume"),
        (["--seeds", "0-1", "--retrain", "td3", "--resume"], "--retrain: must be one of ppo, sac"),
        (["--seeds", "0-2", "--retrain", "sac", "--resume"], "started with other parameters"),  # another benchmark
    ):
        assert main([*base, *extra]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1, err
    with ResultStore(out) as store:  # nothing removed by a refused command
        assert len(store.done_keys()) == 2


def test_a_saved_table_joins_this_runs_rows_which_replace_its_cases(tmp_path, capsys):
    from agents.benchmark import join_rows
    from flatbody_env.cli.main import main

    envs = ["FlatBody-v1"]
    saved = {"rows": _rows("ppo", envs, range(3), lambda e, s: 0.5) + _rows("td3", envs, range(3), lambda e, s: 0.0)}
    again = _rows("td3", envs, range(3), lambda e, s: 0.7)
    joined = join_rows(again, saved)
    assert len(joined) == 6
    assert {r["algo"]: r["final"]["success_rate"] for r in joined} == {"ppo": 0.5, "td3": 0.7}
    extra = _rows("td3", envs, [3], lambda e, s: 0.1)  # a seed the saved table lacks joins it
    assert len(join_rows(extra, saved)) == 7
    for bad, words in (([1, 2], "expected a saved benchmark table"), ({"rows": [{"algo": "ppo"}]}, "row 0 is not a")):
        with pytest.raises(ValueError, match=words):
            join_rows([], bad)
    table = tmp_path / "table.json"
    table.write_text(json.dumps({"rows": [{"algo": "ppo", "env_id": "FlatBody-v1"}]}))
    base = ["benchmark", "--algos", "td3", "--envs", "FlatBody-v1", "--seeds", "0-1", "--out", str(tmp_path / "b")]
    for path in (table, tmp_path / "missing.json"):
        assert main([*base, "--with", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("flatbody") and "--with" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "b").exists()  # refused before anything trains


def test_the_saved_side_tables_are_what_docs_say_and_their_own_report():
    """The off-policy runs at PPO's budget (``agents/data/benchmark/off-policy-3e5.json``): their final cells are the
    report of their own rows (mean success and its t-interval over the seeds), and docs/tasks.md quotes those figures
    and each seed's success as they are saved."""
    from pathlib import Path

    from agents.benchmark import DATA_DIR

    saved = json.loads((DATA_DIR / "off-policy-3e5.json").read_text())
    page = (Path(__file__).resolve().parents[2] / "docs" / "tasks.md").read_text(encoding="utf-8")
    for algo in ("sac", "td3"):
        rows = sorted((r for r in saved["rows"] if r["algo"] == algo), key=lambda r: r["seed"])
        assert [r["seed"] for r in rows] == [0, 1, 2, 3, 4] and {r["budget"] for r in rows} == {300_000}
        success = [r["final"]["success_rate"] for r in rows]
        mean, lo, hi = mean_interval(success)
        assert saved["final"]["cells"][f"{algo}|FlatBody-v1"]["success_mean"] == pytest.approx([mean, lo, hi])
        quoted = f"{algo.upper()} **{mean:.0%} ({lo:.0%}–{hi:.0%})**".replace("%", " %")
        seeds = "(" + ", ".join(f"{s * 100:.0f}" for s in success)
        assert quoted in page.replace("\n", " ") and seeds in page.replace("\n", " "), (quoted, seeds)


def test_several_saved_tables_join_in_order_the_first_named_winning(tmp_path):
    """``--with A --with B``: this run's cases replace A's and B's, A's replace B's (a side table named before the
    main table replaces its cases), and the report holds every case once."""
    from agents.benchmark import BUDGETS
    from flatbody_env.cli.main import main
    from flatbody_env.sweep.store import ResultStore
    from flatbody_env.sweep.tasks import plan

    envs = ["FlatBody-v1"]
    spec = {"kind": "benchmark", "algos": ["td3"], "envs": envs, "seeds": [0, 1], "budgets": {**BUDGETS, "td3": 1500},
            "eval_seed": 10000}  # fmt: skip
    out = tmp_path / "b"
    with ResultStore(out) as store:  # a finished benchmark of td3 on seeds 0-1: --resume trains nothing
        store.begin(spec, resume=False)
        for task, row in zip(plan(spec, out), _rows("td3", envs, [0, 1], lambda e, s: 0.9), strict=True):
            store.put(task.key, payload=row)
    side = {"rows": _rows("td3", envs, range(4), lambda e, s: 0.6) + _rows("sac", envs, range(2), lambda e, s: 0.5)}
    main_table = {
        "rows": _rows("td3", envs, range(5), lambda e, s: 0.1) + _rows("ppo", envs, range(2), lambda e, s: 0.3)
    }
    paths = []
    for name, table in (("side", side), ("main", main_table)):
        paths.append(tmp_path / f"{name}.json")
        paths[-1].write_text(json.dumps(table))
    args = ["benchmark", "--algos", "td3", "--envs", "FlatBody-v1", "--seeds", "0-1", "--budget", "td3=1500"]
    assert main([*args, "--out", str(out), "--resume", "--no-progress", "--workers", "0",
                 "--with", str(paths[0]), "--with", str(paths[1])]) == 0  # fmt: skip
    rows = json.loads((out / "benchmark.json").read_text())["rows"]
    got = {(r["algo"], r["seed"]): r["final"]["success_rate"] for r in rows}
    assert len(rows) == len(got) == 5 + 2 + 2
    assert got == {("td3", 0): 0.9, ("td3", 1): 0.9, ("td3", 2): 0.6, ("td3", 3): 0.6, ("td3", 4): 0.1,
                   ("sac", 0): 0.5, ("sac", 1): 0.5, ("ppo", 0): 0.3, ("ppo", 1): 0.3}  # fmt: skip


def test_the_saved_table_is_every_algorithm_on_every_v1_task_at_the_default_budgets():
    """``agents/data/benchmark/benchmark.json`` holds five training seeds of each algorithm on each v1 task, each at its
    algorithm's budget of :data:`agents.benchmark.BUDGETS` (so ``flatbody benchmark --out DIR`` trains this table); its
    ``FlatBody-v1`` cells of SAC and TD3 are the runs of ``off-policy-3e5.json``, and the runs at 10⁵ steps it held
    before are ``off-policy-1e5.json``'s."""
    from agents.benchmark import ALGOS, BUDGETS, DATA_DIR
    from flatbody_env.env.registration import V1_IDS

    rows = json.loads((DATA_DIR / "benchmark.json").read_text())["rows"]
    cases = {(r["algo"], r["env_id"], r["seed"]) for r in rows}
    assert len(cases) == len(rows) == len(ALGOS) * len(V1_IDS) * 5
    assert cases == {(a, e, s) for a in ALGOS for e in V1_IDS for s in range(5)}
    assert all(r["budget"] == BUDGETS[r["algo"]] for r in rows)
    side = json.loads((DATA_DIR / "off-policy-3e5.json").read_text())["rows"]
    mine = {(r["algo"], r["seed"]): r for r in rows if r["env_id"] == "FlatBody-v1" and r["algo"] in ("sac", "td3")}
    assert {(r["algo"], r["seed"]): r for r in side} == mine
    before = json.loads((DATA_DIR / "off-policy-1e5.json").read_text())["rows"]
    assert len(before) == 2 * len(V1_IDS) * 5 and {r["budget"] for r in before} == {100_000}
