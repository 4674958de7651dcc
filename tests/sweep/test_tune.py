"""``flatbody tune``: search space checks, pruning, a journal-file study and a PostgreSQL study
shared by two workers, and retraining a tuned trial with ``flatbody train --study``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

optuna = pytest.importorskip("optuna")

from agents.tune import TuneConfig, as_overrides, load_search_space, objective, open_storage  # noqa: E402

SMALL = str(Path(__file__).with_name("ppo_search_small.yml"))
FIXED = [
    "--n-timesteps",
    "128",
    "--n-envs",
    "2",
    "--evaluations",
    "2",
    "--eval-episodes",
    "2",
    "--search-file",
    SMALL,
    "--hyperparams",
    "n_steps=64",
    "batch_size=64",
]


def _ok(r):
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def test_shipped_search_spaces_load_and_name_yaml_keys():
    from agents.config import apply_overrides, load_hyperparams

    from agents.tune import ENV_ID

    for algo in ("ppo", "sac"):
        space = load_search_space(algo)
        hp = load_hyperparams(algo, ENV_ID)  # the searched task's entry
        for name in space:  # every searched key exists in the algorithm's YAML (dotted: inside a mapping)
            node = hp
            for part in name.split("."):
                assert part in node, (algo, name)
                node = node[part]
        mid = {k: (v["choices"][0] if v["type"] == "categorical" else v["low"]) for k, v in space.items()}
        applied = apply_overrides(hp, as_overrides(mid))
        assert all(eval_key(applied, k) == v for k, v in mid.items())


def eval_key(hp, dotted):
    for part in dotted.split("."):
        hp = hp[part]
    return hp


@pytest.mark.parametrize(
    "entry,match",
    [
        ({"x": {"type": "uniform", "low": 0, "high": 1}}, "type"),
        ({"x": {"type": "float", "low": 1, "high": 1}}, "low < high"),
        ({"x": {"type": "float", "low": 0, "high": 1, "log": True}}, "log scale"),
        ({"x": {"type": "categorical", "choices": []}}, "choices"),
    ],
)
def test_bad_search_space_names_the_entry(tmp_path, entry, match):
    f = tmp_path / "s.yml"
    f.write_text(yaml.safe_dump({"FlatBody-v0": entry}))
    with pytest.raises(ValueError, match=match):
        load_search_space("ppo", path=f)


@pytest.mark.parametrize(("steps", "evaluations"), [(512, 0), (512, 513), (10**9, 1001)])
def test_evaluations_per_trial_are_bounded(tmp_path, steps, evaluations):
    # one evaluation per pruner step: at least one, at most one per step and 1,000 in all (never a hang)
    with pytest.raises(ValueError, match="^evaluations"):
        TuneConfig(algo="ppo", study="s", storage=str(tmp_path / "j.log"), n_timesteps=steps, evaluations=evaluations)


def test_pruned_trial_stops_training_early(tmp_path):
    cfg = TuneConfig(
        algo="ppo",
        study="prune",
        storage=str(tmp_path / "j.log"),
        trials=1,
        n_timesteps=512,
        evaluations=4,
        eval_episodes=2,
        n_envs=2,
        search_file=SMALL,
        overrides=("n_steps=64", "batch_size=64"),
        out=str(tmp_path),
    )
    # a final distance is > 0, so this pruner prunes at the first report
    study = optuna.create_study(pruner=optuna.pruners.ThresholdPruner(upper=0.0), direction="minimize")
    study.optimize(lambda t: objective(t, cfg, load_search_space("ppo", path=SMALL)), n_trials=1)
    (trial,) = study.trials
    assert trial.state == optuna.trial.TrialState.PRUNED
    assert list(trial.intermediate_values) == [0] and trial.intermediate_values[0] > 0
    run = json.loads((tmp_path / "prune" / "trial-0" / "run.json").read_text())
    assert run["n_timesteps"] < 512  # stopped after the first evaluation, at 128 steps (two 64-step rollouts of 2 envs)


def test_an_infeasible_point_is_pruned_with_its_reason_and_a_fixed_key_is_not_searched(tmp_path):
    """A drawn batch_size above n_steps x n_envs is pruned before training (no traceback, no run folder), the reason
    kept with the trial; a key the user fixes with --hyperparams is left out of the search space."""
    from agents.tune import tune_worker

    space = {
        "batch_size": {"type": "categorical", "choices": [4096]},
        "n_steps": {"type": "categorical", "choices": [8]},
    }
    search = tmp_path / "space.yml"
    search.write_text(yaml.safe_dump({"FlatBody-v0": space}))
    cfg = TuneConfig(algo="ppo", study="infeasible", storage=str(tmp_path / "j.log"), trials=1, n_timesteps=128,
                     evaluations=1, eval_episodes=1, n_envs=2, search_file=str(search), out=str(tmp_path))  # fmt: skip
    study = optuna.create_study(direction="minimize")
    study.optimize(lambda t: objective(t, cfg, load_search_space("ppo", path=str(search))), n_trials=1)
    (trial,) = study.trials
    assert trial.state == optuna.trial.TrialState.PRUNED
    assert "batch_size" in trial.user_attrs["infeasible"] and "n_steps" in trial.user_attrs["infeasible"]
    assert not (tmp_path / "infeasible" / "trial-0").exists()
    fixed = TuneConfig(**{**vars(cfg), "study": "fixed", "overrides": ("n_steps=64", "batch_size=64")})
    assert tune_worker(fixed) == 1
    (trial,) = optuna.load_study(study_name="fixed", storage=open_storage(cfg.storage)).trials
    assert trial.params == {} and trial.state == optuna.trial.TrialState.COMPLETE  # nothing left to search: trained


def _check_study(storage: str, name: str, trials: int) -> list:
    study = optuna.load_study(study_name=name, storage=open_storage(storage))
    done = study.get_trials(deepcopy=False)
    assert len(done) == trials
    states = {optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED}
    assert all(t.state in states for t in done)
    for t in done:
        assert 1e-4 <= t.params["learning_rate"] <= 1e-3 and -2.0 <= t.params["policy_kwargs.log_std_init"] <= -0.5
        assert len(t.intermediate_values) >= 1
    assert len({t.user_attrs["worker"] for t in done}) == 2  # two workers shared the study
    assert study.user_attrs["algo"] == "ppo"
    return done


@pytest.mark.slow  # trains agents: a training check (pytest -m slow)
def test_journal_study_shared_by_two_workers_and_retrained(cli, tmp_path):
    journal = str(tmp_path / "optuna.log")
    rep = json.loads(
        _ok(
            cli(
                "tune",
                "--algo",
                "ppo",
                "--trials",
                "3",
                *FIXED,
                "--storage",
                journal,
                "--study",
                "j",
                "--out",
                str(tmp_path / "runs"),
                "--workers",
                "2",
                "--json",
            )
        )
    )
    assert len(rep["trials"]) == 3
    done = _check_study(journal, "j", 3)
    best = min((t for t in done if t.state == optuna.trial.TrialState.COMPLETE), key=lambda t: t.value)
    assert rep["best"]["number"] == best.number
    out = tmp_path / "retrain"
    _ok(
        cli(
            "train",
            "--study",
            "j",
            "--trial-id",
            str(best.number),
            "--storage",
            journal,
            "--n-timesteps",
            "64",
            "--out",
            str(out),
            "--no-progress",
        )
    )
    hp = yaml.safe_load((out / "config.yml").read_text())["hyperparams"]
    assert hp["learning_rate"] == best.params["learning_rate"]
    assert hp["policy_kwargs"]["log_std_init"] == best.params["policy_kwargs.log_std_init"]
    assert hp["n_steps"] == 64 and hp["n_envs"] == 2  # the study's fixed settings come along
    r = cli("train", "--study", "j", "--trial-id", "99", "--storage", journal)
    assert r.returncode == 2 and "trial_id" in r.stderr


@pytest.mark.slow  # long: starts a PostgreSQL server and two search workers
def test_postgresql_study_shared_by_two_workers(cli, postgres_url, tmp_path):
    rep = json.loads(
        _ok(
            cli(
                "tune",
                "--algo",
                "ppo",
                "--trials",
                "2",
                *FIXED,
                "--storage",
                postgres_url,
                "--study",
                "pg",
                "--out",
                str(tmp_path / "runs"),
                "--workers",
                "2",
                "--json",
            )
        )
    )
    assert rep["study"] == "pg" and len(rep["trials"]) == 2
    _check_study(postgres_url, "pg", 2)


def test_unreachable_database_is_one_line(cli):
    r = cli("tune", "--algo", "ppo", "--trials", "1", "--storage", "postgresql://nobody@127.0.0.1:1/none")
    assert r.returncode == 2 and "storage: cannot open" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("left, workers", [(3, 2), (7, 3), (1, 4), (0, 2), (8, 8)])
def test_trial_shares_sum_exactly_to_the_trials_left(left, workers):
    from agents.tune import shares

    got = shares(left, workers)
    assert sum(got) == left and len(got) <= workers and all(n >= 1 for n in got)
    assert not got or max(got) - min(got) <= 1


def test_trial_shares_refuse_no_workers():
    from agents.tune import shares

    with pytest.raises(ValueError, match="workers"):
        shares(3, 0)
