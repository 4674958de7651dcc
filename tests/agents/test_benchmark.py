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


def test_curves_table_files_and_docs_block_come_from_the_rows(tmp_path):
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
    block = markdown(saved, "flatbody benchmark --algos ppo,sac")
    assert "flatbody benchmark --algos ppo,sac" in block and "FlatBodySlow-v1" in block
