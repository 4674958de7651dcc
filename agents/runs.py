"""One run folder: where every trainer writes, the one way.

``flatbody train`` (SB3's PPO, SAC, TD3 and rsl_rl's PPO), ``flatbody curriculum`` and ``flatbody imitate clone``
write their run through a :class:`RunFolder`::

    OUT/config.yml          everything to continue or train the run again (agents.config.RunConfig: algorithm, env id
                            and version, env keywords, hyperparameters after overrides, seed, budget, device, prior)
    OUT/run.json            what ran it: command, git hash, machine, versions, wall time, steps trained
    OUT/progress.csv        the training log (SB3's logger, or one row per rsl-ppo iteration)
    OUT/evaluations.csv     with --eval-freq: the policy on held-out episodes along the run (agents.evaluate)
    OUT/model.zip           the SB3 model (rsl-ppo: its actor exported as an SB3 PPO model)
    OUT/vecnormalize.pkl    VecNormalize statistics (SB3 runs that normalise)
    OUT/policy.npz          the deterministic policy for numpy (agents.numpy_policy: evaluate and demo without torch)
    OUT/rsl_model.pt        rsl_rl's own actor and critic (rsl-ppo)
    OUT/checkpoints/        while the run goes on: every checkpoint_freq steps, the newest KEEP_CHECKPOINTS kept,
                            removed after a completed run unless --keep-checkpoints; --resume continues from them

The rules, in one place: a new run refuses a folder that holds one, the shipped agents' folder, ``/``, the home
folder or a folder above it (``--force`` replaces a run, never the last three); nothing is written before the
configuration is checked; every file goes through :mod:`flatbody_env.output` (atomic, no planted link followed, the
file named on failure); the folder becomes trusted (its pickles load without ``--trust``,
:func:`agents.numpy_policy.remember_run`) when ``config.yml``, its first file, is in place; every pickle read back
(``--resume``, fine-tuning) goes through the one trust check (:func:`agents.numpy_policy.read_pickled`).
"""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from agents.config import RunConfig
from flatbody_env.output import atomic_path, atomic_write, write_csv

KEEP_CHECKPOINTS = 3
"""Checkpoints kept during a run (the newest; older ones are removed as new ones are written): enough that a newest
one damaged by a crash leaves a good one to ``--resume`` from."""
RUN_FILES = ("model.zip", "config.yml", "run.json", "checkpoints")
"""A folder holding any of these holds a run (a new run refuses it without ``--force``)."""
_CHECKPOINT = re.compile(r"(rl|rsl)_model_(?:([a-z_]+)_)?(\d+)_steps\.(zip|pkl|pt|json)")


@dataclass(frozen=True, kw_only=True)
class TrainResult:
    """What a training run did: its folder, the steps trained in all, the wall time of this run (seconds) and the
    step it resumed from (None: it started from step 0)."""

    out: Path
    timesteps: int
    wall_time_s: float
    resumed_from: int | None


@dataclass(frozen=True, kw_only=True)
class Checkpoint:
    """The files of one checkpoint (:meth:`RunFolder.checkpoints`); None where a kind is absent."""

    steps: int
    model: Path
    vecnormalize: Path | None = None
    replay_buffer: Path | None = None
    state: Path | None = None
    """A trainer's own state beside the model (the curriculum's stage), JSON."""


class ProgressTable:
    """A training log kept in memory and written to ``path`` as it grows, through the one writing door
    (:func:`flatbody_env.output.write_csv`: atomic, no planted link followed).

    The file is rewritten after a row once the last rewrite is a while ago (at least 2 s, and ten times as long as the
    rewrite took, so the cost stays a small share of the run however long it is), and when the table is closed (then
    always, so a run too short for a row has an empty table): a killed run leaves the table of its last rewrite, never
    a half-written file. Columns are added as they appear (sorted among themselves with ``sort``, as SB3's logger
    gives them; else the first row's order is the header's); earlier rows leave them empty (as SB3's format does)."""

    def __init__(self, path: Path, *, sort: bool = True) -> None:
        self.path, self.keys, self.rows, self.sort = Path(path), [], [], sort
        self.written, self.cost, self.dirty = -math.inf, 0.0, False

    def add(self, row: dict[str, Any]) -> None:
        """Append one row (values None are left empty)."""
        new = [k for k in row if k not in self.keys]
        self.keys.extend(sorted(new) if self.sort or self.keys else new)
        self.rows.append({k: v for k, v in row.items() if v is not None})
        self.dirty = True
        if time.monotonic() - self.written >= max(2.0, 10.0 * self.cost):
            self.flush()

    def flush(self) -> None:
        """Write the table now if it changed since the last write."""
        if not self.dirty:
            return
        t0 = time.monotonic()
        write_csv(self.path, self.keys, ([row.get(k, "") for k in self.keys] for row in self.rows))
        self.written, self.dirty = time.monotonic(), False
        self.cost = self.written - t0

    def close(self) -> None:
        """The last write (also of an empty table)."""
        self.dirty = self.dirty or not self.path.exists()
        self.flush()


@dataclass(frozen=True, kw_only=True)
class RunFolder:
    """The folder of one training run (module docstring); ``path`` as given."""

    path: Path

    # -- opening ------------------------------------------------------------------------------------------------
    @classmethod
    def new(cls, out: str | Path, *, force: bool = False) -> RunFolder:
        """The folder of a new run, checked; nothing is written yet (:meth:`start` writes the first file).

        Raises
        ------
        ValueError
            Naming ``out``: the folder can never be trusted (:func:`agents.numpy_policy.trust_refusal`: ``/``, the
            home folder or a folder above it), or — unless ``force`` — it is the shipped agents' folder
            (``agents/models/…``) or already holds a run (:data:`RUN_FILES`); the message says that ``--force``
            replaces it.
        """
        from agents.numpy_policy import MODELS_DIR, trust_refusal

        if not isinstance(out, (str, Path)) or not str(out) or "\0" in str(out):
            raise ValueError(f"out: expected a folder path, got {str(out)[:60]!r}")
        path = Path(out)
        reason = trust_refusal(path)
        if reason is not None:  # the run would make the folder trusted (agents.numpy_policy.remember_run)
            raise ValueError(
                f"out: {str(path)[:80]!r} {reason}; a run's folder becomes trusted (its pickles load without --trust), "
                "so give the run a folder of its own, e.g. runs/ppo"
            )
        if path.exists() and not path.is_dir():
            raise ValueError(f"out: {str(path)[:80]!r} exists and is not a directory")
        if not force:
            if path.resolve().is_relative_to(MODELS_DIR.resolve()):
                raise ValueError(
                    f"out: {str(path)!r} is the shipped agent's folder; --force overwrites it "
                    "(or give another --out, e.g. runs/ppo)"
                )
            held = [name for name in RUN_FILES if (path / name).exists()]
            if held:
                raise ValueError(
                    f"out: {str(path)!r} already holds a training run ({', '.join(held)}); --force overwrites it "
                    "(--resume continues it)"
                )
        return cls(path=path)

    @classmethod
    def existing(cls, out: str | Path, *, where: str = "resume") -> RunFolder:
        """The folder of a run that exists (it holds ``config.yml``), e.g. to resume it; ``ValueError`` naming
        ``where`` otherwise."""
        path = Path(out)
        if not os.path.lexists(path / "config.yml"):  # anything else there is read through the door (and refused)
            raise ValueError(f"{where}: {str(path)[:80]!r} holds no run (no config.yml)")
        return cls(path=path)

    # -- configuration -------------------------------------------------------------------------------------------
    @property
    def checkpoint_dir(self) -> Path:
        return self.path / "checkpoints"

    def config(self) -> RunConfig:
        """The run's configuration (``config.yml``, read through the one reading door and checked)."""
        return RunConfig.read(self.path)

    def start(self, config: RunConfig, *, force: bool = False) -> None:
        """Begin the run: the folder created, a forced run's old checkpoints removed (a later ``--resume`` would
        continue them), ``config.yml`` written — the run's first file — and the folder trusted from then on."""
        from agents.numpy_policy import remember_run

        self.path.mkdir(parents=True, exist_ok=True)
        if force:
            self.remove_checkpoints()
        self.write_config(config)
        remember_run(self.path)  # the run's first file is in place: its folder is this user's (docs/reliability.md)

    def write_config(self, config: RunConfig, **extra: Any) -> Path:
        """``config.yml``: the configuration's mapping (:meth:`agents.config.RunConfig.mapping`) and ``extra`` keys
        (information, e.g. a curriculum's stages reached)."""
        text = yaml.safe_dump({**config.mapping(), **extra}, sort_keys=False)
        return atomic_write(self.path / "config.yml", text)

    # -- files --------------------------------------------------------------------------------------------------
    def save(self, name: str, writer: Callable[[Path], Any]) -> Path:
        """Write the file ``name`` of the run by ``writer(temporary path)`` (a library's own ``save``), atomically:
        a killed run leaves the previous file, never half of one."""
        with atomic_path(self.path / name) as tmp:
            writer(tmp)
        return self.path / name

    def write_progress(self, rows: list[dict[str, Any]], name: str = "progress.csv") -> Path | None:
        """``progress.csv`` of rows (the first row's keys are the header); nothing when there are none."""
        if not rows:
            return None
        return write_csv(self.path / name, list(rows[0]), ([r.get(k, "") for k in rows[0]] for r in rows))

    def progress_logger(self, subfolder: str = ""):
        """SB3's logger writing ``progress.csv`` (in ``subfolder`` of the run, for a resumed part) through the one
        writing door (:func:`flatbody_env.output.write_csv`: atomic, no planted link followed) instead of SB3's own
        CSV format, which writes into the final name as it goes.

        The table is kept in memory and the file rewritten after a dump once the last rewrite is a while ago (at
        least 2 s, and ten times as long as the rewrite took, so the cost stays a small share of the run however long
        it is), and when the logger is closed (then always, so a run too short for a row has an empty table): a killed
        run leaves the table of its last rewrite, never a half-written file. Columns are added, in sorted order, as they appear; earlier rows leave them empty (as SB3's format
        does)."""
        from stable_baselines3.common.logger import KVWriter, Logger, filter_excluded_keys

        class AtomicCSV(KVWriter):
            def __init__(self, path: Path) -> None:
                self.table = ProgressTable(path)

            def write(self, key_values, key_excluded, step: int = 0) -> None:
                self.table.add(filter_excluded_keys(key_values, key_excluded, "csv"))

            def close(self) -> None:
                self.table.close()

        folder = self.path / subfolder if subfolder else self.path
        folder.mkdir(parents=True, exist_ok=True)
        return Logger(folder=str(folder), output_formats=[AtomicCSV(folder / "progress.csv")])

    def progress_table(self, name: str = "progress.csv") -> ProgressTable:
        """The run's training log ``name`` as a :class:`ProgressTable` (rsl-ppo's rows; SB3's go through
        :meth:`progress_logger`, which writes through the same table)."""
        return ProgressTable(self.path / name, sort=False)

    def evaluations_table(self, resumed_from: int | None = None) -> ProgressTable:
        """The run's held-out evaluations (:class:`agents.evaluate.HeldOutEvaluations`) as a table: ``evaluations.csv``,
        or ``evaluations-resumed-N.csv`` for the part of a run resumed from N steps (as its progress log)."""
        name = "evaluations.csv" if resumed_from is None else f"evaluations-resumed-{resumed_from}.csv"
        return ProgressTable(self.path / name, sort=False)

    def write_run(
        self,
        config: RunConfig,
        *,
        timesteps: int,
        wall_time_s: float,
        command: list[str] | None = None,
        resumed_from: int | None = None,
        threads: int = 1,
        **extra: Any,
    ) -> Path:
        """``run.json``: what ran the run (:mod:`flatbody_env.provenance`: the command, git hash, machine, versions),
        the steps trained in all and the wall time (a resumed run's: with the earlier parts', :meth:`previous_wall_time`)."""
        from flatbody_env.provenance import git_hash, invocation, machine, versions

        run = {
            **invocation(command),
            "git_hash": git_hash(),
            "algo": config.algo,
            "env_id": config.env_id,
            "env_version": config.env_version,
            "seed": config.seed,
            "device": config.device,
            "n_timesteps": int(timesteps),
            "n_envs": config.n_envs,
            "torch_threads": threads,
            "wall_time_s": round(float(wall_time_s), 1),
            "resumed_from": resumed_from,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "machine": machine(),
            "versions": versions("numpy", "gymnasium", "torch", "stable_baselines3", "rsl-rl-lib"),
            **extra,
        }
        return atomic_write(self.path / "run.json", json.dumps(run, indent=2) + "\n")

    def previous_wall_time(self) -> float:
        """The ``wall_time_s`` of the run so far (its ``run.json``, read through the one reading door: a file that is
        not a regular JSON file of bounded size is a ``ValueError`` naming ``run.json``; 0 when there is none, or no
        finite number ≥ 0 in it). A resumed run reads it before it trains."""
        from flatbody_env.physics import validation

        if not os.path.lexists(self.path / "run.json"):
            return 0.0
        run = validation.read_json("run.json", self.path / "run.json")
        value = run.get("wall_time_s", 0.0) if isinstance(run, dict) else 0.0
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0
        return float(value) if ok else 0.0

    def export_policy(self) -> Path | None:
        """``policy.npz`` beside the model (:func:`agents.numpy_policy.export_policy`), so that evaluate, demo and
        record run the agent with numpy alone; a policy the numpy evaluator cannot run is a note on stderr (they use
        SB3 then), not an error of the run."""
        from agents.numpy_policy import export_policy

        try:
            return export_policy(self.path)
        except ValueError as exc:
            print(
                f"flatbody: note: no policy.npz exported ({' '.join(str(exc).split())[:200]}); "
                "evaluate and demo use Stable-Baselines3",
                file=sys.stderr,
            )
            return None

    # -- checkpoints ------------------------------------------------------------------------------------------------
    def checkpoints(self) -> list[Checkpoint]:
        """Every checkpoint of the run whose model file is there, the newest first (temporary files never listed)."""
        found: dict[int, dict[str, Path]] = {}
        folder = self.checkpoint_dir
        for f in folder.iterdir() if folder.is_dir() else ():
            m = _CHECKPOINT.fullmatch(f.name)
            if m:
                kind = "model" if m.group(2) is None else m.group(2)
                found.setdefault(int(m.group(3)), {})[kind] = f
        return [
            Checkpoint(
                steps=steps,
                model=files["model"],
                vecnormalize=files.get("vecnormalize"),
                replay_buffer=files.get("replay_buffer"),
                state=files.get("state"),
            )
            for steps, files in sorted(found.items(), reverse=True)
            if "model" in files
        ]

    def save_checkpoint(
        self, steps: int, writers: dict[str, Callable[[Path], Any]], *, prefix: str = "rl_model"
    ) -> Path:
        """One checkpoint at ``steps``: a file per kind of ``writers`` (``vecnormalize``, ``replay_buffer``, ``state``
        and last ``model``, so that a checkpoint whose model is there is whole), each atomic, named as
        :meth:`checkpoints` reads them; then all but the :data:`KEEP_CHECKPOINTS` newest removed. Returns the model's
        path."""
        folder = self.checkpoint_dir
        folder.mkdir(parents=True, exist_ok=True)
        suffix = {"vecnormalize": "pkl", "replay_buffer": "pkl", "state": "json"}
        model_suffix = "pt" if prefix == "rsl_model" else "zip"
        for kind, writer in writers.items():
            if kind != "model":
                with atomic_path(folder / f"{prefix}_{kind}_{steps}_steps.{suffix[kind]}") as tmp:
                    writer(tmp)
        model = folder / f"{prefix}_{steps}_steps.{model_suffix}"
        with atomic_path(model) as tmp:
            writers["model"](tmp)
        self.rotate_checkpoints(KEEP_CHECKPOINTS)
        return model

    def rotate_checkpoints(self, keep: int) -> None:
        """Remove all but the ``keep`` newest checkpoints: every file of a checkpoint, grouped by its step count."""
        steps: dict[int, list[Path]] = {}
        folder = self.checkpoint_dir
        for f in folder.iterdir() if folder.is_dir() else ():
            m = _CHECKPOINT.fullmatch(f.name)
            if m:
                steps.setdefault(int(m.group(3)), []).append(f)
        for n in sorted(steps, reverse=True)[keep:]:
            for f in steps[n]:
                f.unlink(missing_ok=True)

    def remove_checkpoints(self) -> None:
        if self.checkpoint_dir.is_dir():
            shutil.rmtree(self.checkpoint_dir)

    def finish(self, *, keep_checkpoints: bool = False) -> None:
        """After a completed run: the checkpoints removed unless ``keep_checkpoints``."""
        if not keep_checkpoints:
            self.remove_checkpoints()


def resume_command(config: RunConfig, folder: RunFolder) -> str:
    """The complete command that continues the run in ``folder`` (printed when a run is stopped)."""
    argv = ["flatbody", "train", "--algo", config.algo, "--env", config.env_id, "--out", str(folder.path), "--resume"]
    if config.device != "cpu":
        argv += ["--device", config.device]
    return shlex.join(argv)


def stopped(
    config: RunConfig, folder: RunFolder, steps: int, checkpoint: Path | None, why: str = ""
) -> KeyboardInterrupt:
    """The one-line ``KeyboardInterrupt`` of a run stopped by Ctrl-C: where it stopped, the checkpoint kept and the
    command that continues it (or why none was kept)."""
    if checkpoint is None:
        return KeyboardInterrupt(f"training stopped at {steps} steps; no checkpoint saved ({why})")
    return KeyboardInterrupt(
        f"training stopped at {steps} steps; checkpoint {checkpoint}: {resume_command(config, folder)} continues"
    )


__all__ = [
    "Checkpoint",
    "KEEP_CHECKPOINTS",
    "RUN_FILES",
    "ProgressTable",
    "RunFolder",
    "TrainResult",
    "resume_command",
    "stopped",
]
