"""Hyperparameter search with Optuna, as RL Zoo does it: TPE sampler, median pruner.

The search space lives beside the hyperparameters, in ``hyperparams/<algo>_search.yml`` (keyed by
environment id like ``<algo>.yml``); each entry names a key of ``<algo>.yml`` (dotted keys reach
into mappings, e.g. ``policy_kwargs.log_std_init``) and how to sample it::

    learning_rate: {type: float, low: 1.0e-5, high: 1.0e-3, log: true}
    n_epochs: {type: int, low: 3, high: 10}
    gamma: {type: categorical, choices: [0.98, 0.99, 0.995]}

A trial trains ``algo`` with the YAML hyperparameters plus the sampled ones for a short budget
(:func:`agents.train.train`), evaluates the agent ``evaluations`` times along the way
(:class:`agents.evaluate.HeldOutEvaluations`, as ``flatbody train --eval-freq`` and the benchmark do) on
``eval_episodes`` episodes seeded from :data:`TUNE_EVAL_SEED` (held apart from the training
episodes, seeded from the training seed, and from ``flatbody evaluate``'s episodes, seeded from
10000), reports each mean final distance to the pruner and stops early when the median pruner says
so. The objective is the mean final distance to the target after training (minimised); the success
rate is kept as a trial attribute.

Storage: a journal file (``optuna.storages.JournalStorage`` on a file; several processes on one
machine or a shared file system may share it) or a database URL (``postgresql://…``, ``mysql://…``,
``sqlite:///…``) for workers on several machines. The study records what a retrain needs (algo,
fixed overrides, hyperparameter file); :func:`trial_overrides` gives a trial's hyperparameters back
as ``key=value`` overrides for ``flatbody train --study NAME --trial-id K``.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.config import HYPERPARAMS_DIR
from agents.config import SB3_ALGOS as ALGOS

ENV_ID = "FlatBody-v0"
"""The task a search trains on (the entries of ``<algo>_search.yml``; the prior track's residual agent)."""
TUNE_EVAL_SEED = 50_000
"""First episode seed of the tuning evaluations (held apart from training and from ``evaluate``)."""
DEFAULT_STORAGE = "sqlite:///runs/tune/optuna.sqlite3"
"""The default storage: an SQLite database through Optuna's RDBStorage, which has a heartbeat (a
journal file has none: trials of a killed worker would stay RUNNING for ever)."""
HEARTBEAT_INTERVAL = int(os.environ.get("FLATBODY_TUNE_HEARTBEAT", "20") or 20)
"""Seconds between a running trial's heartbeats (database storages; ``$FLATBODY_TUNE_HEARTBEAT``)."""
GRACE_PERIOD = 3 * HEARTBEAT_INTERVAL
"""A RUNNING trial with no heartbeat for this long belongs to a killed worker: Optuna marks it FAIL
(when the next trial starts, and in :func:`prepare` / :func:`summary`) and calls :func:`on_failed_trial`."""
_TYPES = ("float", "int", "categorical")


@dataclass(frozen=True, kw_only=True)
class TuneConfig:
    """One search.

    Attributes
    ----------
    algo : str
        ``"ppo"`` or ``"sac"``.
    study : str
        Study name (shared by every worker of the search).
    storage : str
        Journal file path or database URL (see :func:`open_storage`).
    trials : int
        Trials in the study (over all workers).
    n_timesteps : int
        Training budget of one trial (environment steps).
    evaluations : int
        Intermediate evaluations per trial (the pruner's steps).
    eval_episodes : int
        Episodes per evaluation.
    n_envs : int or None
        Parallel bodies while training (default: the YAML's).
    seed : int
        Training seed of every trial (the sampler's seed is ``seed`` + worker index).
    overrides : tuple of str
        Fixed ``key=value`` overrides applied before the sampled ones.
    hyperparams_file, search_file : str or None
        Default: ``hyperparams/<algo>.yml`` and ``hyperparams/<algo>_search.yml``.
    out : str
        Folder of the trials' runs (``OUT/STUDY/trial-K``).
    startup_trials : int
        Trials sampled at random before TPE models the others and before the pruner prunes.
    """

    algo: str
    study: str
    storage: str = DEFAULT_STORAGE
    trials: int = 20
    n_timesteps: int = 20_000
    evaluations: int = 4
    eval_episodes: int = 20
    n_envs: int | None = None
    seed: int = 0
    overrides: tuple[str, ...] = ()
    hyperparams_file: str | None = None
    search_file: str | None = None
    out: str = "runs/tune"
    startup_trials: int = 3

    def __post_init__(self) -> None:
        from flatbody_env.physics import validation

        validation.string("algo", self.algo, choices=ALGOS)
        for name, low in (
            ("trials", 1),
            ("n_timesteps", 1),
            ("eval_episodes", 1),
            ("seed", 0),
            ("startup_trials", 0),
        ):
            validation.integer(name, getattr(self, name), low=low)
        # one evaluation per pruner step, at most the evaluations a run may hold (HeldOutEvaluations.every)
        validation.integer("evaluations", self.evaluations, low=1, high=min(validation.MAX_REPEATS, self.n_timesteps))
        validation.requirement(
            "study", self.study, isinstance(self.study, str) and self.study != "", "be a non-empty name"
        )


# ---------------------------------------------------------------------------------------------
def load_search_space(algo: str, env_id: str = ENV_ID, path: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """The search space of ``env_id`` in ``hyperparams/<algo>_search.yml`` (or ``path``), checked.

    Raises
    ------
    ValueError
        Naming the file or the entry and what is allowed.
    """
    from flatbody_env.physics import validation

    validation.string("algo", algo, choices=ALGOS)

    file = Path(path) if path else HYPERPARAMS_DIR / f"{algo}_search.yml"
    data = validation.read_yaml("search_file", file) or {}  # the one reading door: bounded, no alias bombs
    if not isinstance(data, dict) or env_id not in data or not isinstance(data[env_id], dict) or not data[env_id]:
        raise ValueError(f"search_file: no search space for {env_id!r} in {file}")
    space = data[env_id]
    for name, spec in space.items():
        where = f"search_file: {name}"
        if not isinstance(spec, dict) or spec.get("type") not in _TYPES:
            raise ValueError(f"{where}: needs type: one of {', '.join(_TYPES)}")
        if spec["type"] == "categorical":
            if not isinstance(spec.get("choices"), list) or not spec["choices"]:
                raise ValueError(f"{where}: a categorical needs a non-empty list of choices")
        else:
            lo, hi = spec.get("low"), spec.get("high")
            if (
                not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (lo, hi))
                or not lo < hi
            ):
                raise ValueError(f"{where}: needs finite low < high, got low={lo!r}, high={hi!r}")
            if spec.get("log") and lo <= 0:
                raise ValueError(f"{where}: a log scale needs low > 0, got {lo!r}")
    return space


def sample(trial, space: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """One point of ``space`` suggested by ``trial`` (an ``optuna.Trial``)."""
    params: dict[str, Any] = {}
    for name, spec in space.items():
        if spec["type"] == "float":
            params[name] = trial.suggest_float(
                name, float(spec["low"]), float(spec["high"]), log=bool(spec.get("log", False))
            )
        elif spec["type"] == "int":
            params[name] = trial.suggest_int(
                name, int(spec["low"]), int(spec["high"]), log=bool(spec.get("log", False))
            )
        else:
            params[name] = trial.suggest_categorical(name, spec["choices"])
    return params


def as_overrides(params: dict[str, Any]) -> list[str]:
    """``key=value`` overrides for :func:`agents.train.apply_overrides`, each value written as YAML
    that reads back to the same value (``3e-05`` would read back as a string: YAML 1.1 floats need
    a dot, so the YAML writer's ``3.0e-05`` is used)."""
    return [
        f"{k}={yaml.safe_dump(v, default_flow_style=True).removesuffix(chr(10) + '...' + chr(10)).strip()}"
        for k, v in params.items()
    ]


def open_storage(url: str):
    """An Optuna storage: a database URL (``scheme://…``) as is, anything else a journal file.

    ``journal:PATH`` names a journal file explicitly. The file's folder is created.
    """
    import optuna
    from optuna.storages.journal import JournalFileBackend, JournalStorage

    if not isinstance(url, str) or not url:
        raise ValueError(f"storage: expected a journal file path or a database URL, got {url!r}")
    if url.startswith("journal:"):
        url = url[len("journal:") :]
    elif "://" in url:
        engine: dict[str, Any] = {"pool_pre_ping": True}
        if url.startswith("sqlite:///"):
            from flatbody_env.physics import validation

            db = Path(url[len("sqlite:///") :])
            validation.sqlite_file(
                "storage", db, ("studies",)
            )  # a directory, corrupt or foreign file: one line, exit 2
            db.parent.mkdir(parents=True, exist_ok=True)
            engine["connect_args"] = {"timeout": 60}
        try:
            # Optuna's heartbeat: a killed worker's RUNNING trial is marked FAIL after GRACE_PERIOD
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                return optuna.storages.RDBStorage(
                    url,
                    engine_kwargs=engine,
                    heartbeat_interval=HEARTBEAT_INTERVAL,
                    grace_period=GRACE_PERIOD,
                    heartbeat_stale_trial_callback=on_failed_trial,
                )
        except Exception as exc:  # sqlalchemy's errors: a bad URL, an unreachable server, a missing driver
            raise ValueError(
                f"storage: cannot open {url.split('@')[-1]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})"
            ) from None
    path = Path(url)
    path.parent.mkdir(parents=True, exist_ok=True)
    return JournalStorage(JournalFileBackend(str(path)))


def on_failed_trial(study, trial) -> None:
    """Optuna's ``heartbeat_stale_trial_callback`` (``failed_trial_callback`` before Optuna 4.9): a trial whose
    worker stopped beating (killed) was marked FAIL."""
    sys.stderr.write(
        f"flatbody tune: trial {trial.number} of study {study.study_name!r} lost its worker (no heartbeat for "
        f"{GRACE_PERIOD} s); marked FAIL\n"
    )


def _fail_stale(study) -> None:
    """Mark the trials of killed workers FAIL now (Optuna's heartbeat check; database storages only)."""
    import optuna
    from optuna.storages._heartbeat import is_heartbeat_enabled

    if is_heartbeat_enabled(study._storage):
        with contextlib.suppress(Exception):  # a storage without a heartbeat
            optuna.storages.fail_stale_trials(study)


def prepare(cfg: TuneConfig) -> int:
    """Create the study (and a new database's tables) once, before workers start: two workers
    creating the schema of an empty database at the same instant collide. Returns the number of
    trials still to run (``cfg.trials`` less the finished ones), to be shared out exactly."""
    import optuna

    study = _study(cfg, 0)
    _fail_stale(study)
    finished = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED, optuna.trial.TrialState.FAIL)
    return max(0, cfg.trials - len(study.get_trials(deepcopy=False, states=finished)))


def shares(left: int, workers: int) -> list[int]:
    """Trials per worker: ``left`` split as evenly as possible, summing exactly to ``left`` (workers
    given no trial are left out), so a study of N trials never overshoots when workers finish together."""
    from flatbody_env.physics import validation

    workers = validation.workers("workers", workers)
    left = validation.count("left", left, low=0)
    return [n for n in (left // workers + (i < left % workers) for i in range(workers)) if n > 0]


def _study(cfg: TuneConfig, worker: int = 0):
    import optuna

    sampler = optuna.samplers.TPESampler(seed=cfg.seed + worker, n_startup_trials=cfg.startup_trials)
    pruner = optuna.pruners.MedianPruner(n_startup_trials=cfg.startup_trials, n_warmup_steps=cfg.evaluations // 3)
    study = optuna.create_study(
        study_name=cfg.study,
        storage=open_storage(cfg.storage),
        sampler=sampler,
        pruner=pruner,
        direction="minimize",
        load_if_exists=True,
    )
    fixed = {
        "algo": cfg.algo,
        "overrides": list(cfg.overrides),
        "hyperparams_file": cfg.hyperparams_file,
        "n_envs": cfg.n_envs,
        "tune_n_timesteps": cfg.n_timesteps,
        "env_id": ENV_ID,
    }
    stored = study.user_attrs
    if "algo" in stored and stored["algo"] != cfg.algo:
        raise ValueError(f"study: {cfg.study!r} searches {stored['algo']}, not {cfg.algo}")
    if "algo" not in stored:
        for k, v in fixed.items():
            study.set_user_attr(k, v)
    return study


def objective(trial, cfg: TuneConfig, space: dict[str, dict[str, Any]]) -> float:
    """Train one trial's configuration, evaluating along the way; the final mean distance."""
    import optuna

    from agents.config import resolve
    from agents.evaluate import Agent, HeldOutEvaluations
    from agents.runs import RunFolder
    from agents.train import train_config

    params = sample(trial, space)
    trial.set_user_attr("worker", f"{socket.gethostname()}:{os.getpid()}")
    overrides = [*cfg.overrides, *as_overrides(params)]
    try:  # a point the hyperparameter checks refuse (e.g. batch_size above n_steps x n_envs): pruned before training
        config = resolve(cfg.algo, ENV_ID, seed=cfg.seed, n_timesteps=cfg.n_timesteps, n_envs=cfg.n_envs,
                         overrides=overrides, hyperparams_file=cfg.hyperparams_file)  # fmt: skip
    except ValueError as exc:
        trial.set_user_attr("infeasible", str(exc))
        raise optuna.TrialPruned(f"infeasible: {exc}") from None
    out = Path(cfg.out) / cfg.study / f"trial-{trial.number}"
    every = -(-cfg.n_timesteps // cfg.evaluations)  # at most cfg.evaluations marks, the last at the budget or before

    def report(point) -> bool:
        """Each evaluation's final distance to the trial; False (stop training) when the pruner prunes it."""
        trial.report(point["final_distance"], len(evaluations.points) - 1)
        return not trial.should_prune()

    evaluations = HeldOutEvaluations.every(every, cfg.n_timesteps, ENV_ID, seed=TUNE_EVAL_SEED,
                                           episodes=cfg.eval_episodes, then=report)  # fmt: skip
    train_config(  # the configuration resolved above (flatbody train's path after its own resolve)
        config,
        RunFolder.new(out, force=True),
        checkpoint_freq=0,
        threads=1,
        progress=False,
        evaluations=evaluations,
        force=True,
        notes=False,
        command=["flatbody", "tune", f"--algo={cfg.algo}", f"--study={cfg.study}", f"--trial={trial.number}"],
    )
    if evaluations.stop:
        raise optuna.TrialPruned(f"pruned at evaluation {len(evaluations.points) - 1}")
    final = evaluations.figures(Agent(out))
    trial.set_user_attr("success_rate", final["success_rate"])
    trial.set_user_attr("run", str(out))
    return float(final["final_distance"])


class _QuietInterrupt(logging.Filter):
    """Drop Optuna's log of a trial stopped by Ctrl-C (its traceback, then a second line): the trial
    is stored as failed, and the command says in one line that it was interrupted."""

    def __init__(self) -> None:
        super().__init__()
        self.dropped = ""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if record.exc_info and isinstance(record.exc_info[1], KeyboardInterrupt):
            self.dropped = message.split(" failed", 1)[0] + " failed with value"  # "Trial N failed with value"
            return False
        if self.dropped and message.startswith(self.dropped):
            self.dropped = ""
            return False
        return True


def tune_worker(cfg: TuneConfig, worker: int = 0, n_trials: int | None = None) -> int:
    """Run trials of ``cfg.study`` until it holds ``cfg.trials`` finished trials (or this worker ran
    ``n_trials``); several workers (processes, machines) may run it at once on one storage.
    Returns the number of trials this worker ran."""
    import optuna

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    trial_log = logging.getLogger("optuna.study._optimize")  # the module that logs failed trials
    if not any(isinstance(f, _QuietInterrupt) for f in trial_log.filters):
        trial_log.addFilter(_QuietInterrupt())
    fixed = {item.split("=", 1)[0].strip() for item in cfg.overrides}
    space = {k: v for k, v in load_search_space(cfg.algo, path=cfg.search_file).items() if k not in fixed}
    study = _study(cfg, worker)
    finished = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED, optuna.trial.TrialState.FAIL)
    left = cfg.trials - len(study.get_trials(deepcopy=False, states=finished))
    if left <= 0:
        return 0
    before = {t.number for t in study.get_trials(deepcopy=False)}
    # states=None counts running trials too: a worker stops as soon as the study holds cfg.trials
    # trials in any state, so workers finishing at the same instant are the only way to overshoot
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message=".*mini-batch.*", category=UserWarning
        )  # sampled batch sizes vs rollout size
        study.optimize(
            lambda t: objective(t, cfg, space),
            n_trials=min(left, n_trials or left),
            callbacks=[optuna.study.MaxTrialsCallback(cfg.trials, states=None)],
            catch=(ValueError, RuntimeError),
        )
    return len({t.number for t in study.get_trials(deepcopy=False)} - before)


def summary(study_name: str, storage: str) -> dict[str, Any]:
    """The study's trials (number, state, value, params, success rate) and its best trial."""
    import optuna

    try:
        study = optuna.load_study(study_name=study_name, storage=open_storage(storage))
    except KeyError:
        raise ValueError(f"study: no study {study_name!r} in {storage}") from None
    _fail_stale(study)
    trials = [
        {
            "number": t.number,
            "state": t.state.name,
            "value": t.value,
            "params": t.params,
            "success_rate": t.user_attrs.get("success_rate"),
            "evaluations": len(t.intermediate_values),
        }
        for t in study.get_trials(deepcopy=False)
    ]
    done = [t for t in trials if t["state"] == "COMPLETE"]
    best = min(done, key=lambda t: t["value"]) if done else None
    return {"study": study_name, "algo": study.user_attrs.get("algo"), "trials": trials, "best": best}


def trial_overrides(study_name: str, storage: str, trial_id: int) -> tuple[str, list[str], str | None, int | None]:
    """What ``flatbody train --study NAME --trial-id K`` needs: (algo, overrides, hyperparameter
    file, n_envs) of trial number ``trial_id``; ``ValueError`` naming the field otherwise."""
    import optuna

    try:
        study = optuna.load_study(study_name=study_name, storage=open_storage(storage))
    except KeyError:
        raise ValueError(f"study: no study {study_name!r} in {storage}") from None
    trials = {t.number: t for t in study.get_trials(deepcopy=False)}
    if trial_id not in trials:
        raise ValueError(f"trial_id: study {study_name!r} has trials 0..{len(trials) - 1}, got {trial_id}")
    t = trials[trial_id]
    if not t.params:
        raise ValueError(f"trial_id: trial {trial_id} has no parameters (state {t.state.name})")
    attrs = study.user_attrs
    return (
        attrs["algo"],
        [*attrs.get("overrides", []), *as_overrides(t.params)],
        attrs.get("hyperparams_file"),
        attrs.get("n_envs"),
    )


__all__ = [
    "DEFAULT_STORAGE",
    "TUNE_EVAL_SEED",
    "TuneConfig",
    "as_overrides",
    "load_search_space",
    "objective",
    "open_storage",
    "prepare",
    "sample",
    "summary",
    "trial_overrides",
    "tune_worker",
]
