"""The hostile corpus of bounds and faults (CLI + Python API), with what each case must do.

Every case names its expected outcome:

* ``refuse`` — bad input: CLI exit 2 with one line naming the field (not argparse's "unrecognized
  arguments"), API ``ValueError``. A refused case that exits 0 (or returns) is a **silent accept**.
* ``fail`` — a clean failure: CLI exit 1 (one line), API :class:`IntegrationError` or ``OSError``.
* ``ok`` — valid (e.g. a negative number written ``-2e0``, the largest allowed sizes): exit 0 /
  a finite result.
* ``clean`` — any of the three, as long as it is clean.

Outcomes counted against the package: tracebacks (an exception escaping ``main`` or an API call
that is not ``ValueError`` / ``IntegrationError`` / ``OSError``, or "internal error" lines), hangs
(past the per-case limit), silent accepts, non-finite numbers in a successful output, errors longer
than 3 lines.

``python tests/fuzz/corpus.py [FOLDER]`` runs the whole corpus and prints the tally;
``tests/fuzz/test_bounds.py`` runs it in the test suite (a fast subset by default, all with ``-m slow``).
"""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import hostile

HUGE = ["10000000000000", "1" + "0" * 30, "9" * 400]
"""Integers beyond every documented count bound (MAX_COUNT = 1e9, MAX_SEED = 2**32 - 1)."""
NOT_COUNTS = ["-1", "-2e0", "1.5", "", "nan", "0x10"]
"""Texts no count flag accepts (the lowest bound of a count is 0)."""

# (argv prefix, count flag): every size and count a user can give on the command line
COUNT_FLAGS: list[tuple[tuple[str, ...], str]] = [
    (("bench", "env"), "--steps"),
    (("bench", "env"), "--batch"),
    (("bench", "env"), "--batch-steps"),
    (("bench", "env"), "--episode-steps"),
    (("bench", "env"), "--repeats"),
    (("train", "--algo", "ppo"), "--seed"),
    (("train", "--algo", "ppo"), "--n-timesteps"),
    (("train", "--algo", "ppo"), "--n-envs"),
    (("train", "--algo", "ppo"), "--checkpoint-freq"),
    (("train", "--algo", "ppo"), "--threads"),
    (("train", "--algo", "ppo"), "--eval-freq"),
    (("train", "--algo", "ppo"), "--eval-episodes"),
    (("train", "--algo", "ppo"), "--eval-seed"),
    (("evaluate",), "--episodes"),
    (("evaluate",), "--seed"),
    (("demo",), "--seed"),
    (("record", "--scene", "default"), "--samples"),
    (("record", "--scene", "default"), "--tensor-every"),
    (("record-env",), "--episodes"),
    (("record-env",), "--seed"),
    (("record-env",), "--max-steps"),
    (("record-env",), "--tensor-every"),
    (("simulate", "--scene", "default"), "--samples"),
    (("simulate", "--scene", "default"), "--max-nfev"),
    (("sweep", "stability-map", "--out", "{tmp}/sw"), "--grid"),
    (("sweep", "stability-map", "--out", "{tmp}/sw"), "--chunk"),
    (("sweep", "stability-map", "--out", "{tmp}/sw"), "--workers"),
    (("sweep", "family", "--out", "{tmp}/sf"), "--seeds"),
    (("tune", "--algo", "ppo"), "--trials"),
    (("tune", "--algo", "ppo"), "--n-timesteps"),
    (("tune", "--algo", "ppo"), "--evaluations"),
    (("tune", "--algo", "ppo"), "--eval-episodes"),
    (("tune", "--algo", "ppo"), "--n-envs"),
    (("tune", "--algo", "ppo"), "--workers"),
    (("bench", "sweep"), "--grid"),
    (("bench", "sweep"), "--noop-tasks"),
    (("bench", "sweep"), "--sim-workers"),
    (("serve",), "--workers"),
    (("bench", "service"), "--requests"),
    (("ellipses",), "--grid"),
    (("stability-map",), "--grid"),
]
# (argv prefix, flag, values that must be refused): floats with an upper bound or a floor
FLOAT_FLAGS: list[tuple[tuple[str, ...], str, list[str]]] = [
    (("simulate", "--scene", "default"), "--max-seconds", ["1e9", "86401", "0", "-1", "inf"]),
    (("simulate", "--scene", "default", "--method", "RK4"), "--step", ["1e-12", "1e-30", "1e-7", "0", "-2e0"]),
    (("record", "--scene", "default", "--method", "RK4"), "--step", ["1e-12", "5e-324"]),
    (("bench", "service"), "--seconds", ["1e9", "nan", "-1"]),
    (("sweep", "family", "--out", "{tmp}/sf"), "--step", ["1e300", "0"]),
]


_HELD: list = []
"""Sockets held open while the corpus runs."""


LIMIT_S = 120.0
"""Seconds after which a case counts as a hang: a guard against a run that never ends, not a speed check. The
slowest case takes about 11 s on a quiet 2-core machine (a first env step compiling its kernels); the
wall-clock budget cases (budgets of 0.3–1 s) stop in about 1 s."""


@dataclass
class Case:
    kind: str
    """``cli`` or ``api``."""
    name: str
    expect: str
    argv: list[str] = field(default_factory=list)
    call: Callable[[], Any] | None = None
    limit: float = LIMIT_S


# ------------------------------------------------------------------------------------------ files
def _bad_sqlite(path: Path, kind: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "directory":
        path.mkdir(exist_ok=True)
    elif kind == "corrupt":
        path.write_bytes(b"SQLite format 3\x00" + bytes(range(256)) * 12)
    elif kind == "garbage":
        path.write_bytes(b"hello\n" * 100)
    else:
        db = sqlite3.connect(path)
        db.execute("CREATE TABLE IF NOT EXISTS accounts (id INTEGER)")
        db.commit()
        db.close()


def _trajectories(folder: Path) -> dict[str, Path]:
    from flatbody_env.simulation import simulate

    good = simulate("default", t_end=0.4, times=[0.0, 0.1, 0.2, 0.3, 0.4], with_rotation=True).to_dict()
    out = {}
    for name, change in {
        "lambda0": lambda d: d["state"]["lambda"].__setitem__(2, 0.0),
        "lambda1e-7": lambda d: d["state"]["lambda"].__setitem__(2, 1e-7),
        "lambda_eq_mu": lambda d: d["state"].__setitem__("mu", list(d["state"]["lambda"])),
        "mu_eq_lambda_once": lambda d: d["state"]["mu"].__setitem__(1, d["state"]["lambda"][1]),
        "rho_huge": lambda d: d["state"]["rho"].__setitem__(0, 1e7),
    }.items():
        d = json.loads(json.dumps(good))
        change(d)
        p = folder / f"traj-{name}.json"
        p.write_text(json.dumps(d))
        out[name] = p
    return out


def _model_folders(folder: Path) -> dict[str, Path]:
    """Bad model folders beside copies of a shipped SB3 agent's files."""
    import shutil

    from agents.evaluate import MODELS_DIR

    src = MODELS_DIR / "ppo-FlatBody-v0"  # a shipped SB3 agent with VecNormalize statistics
    made = {}

    def copy(name, files=("model.zip", "config.yml", "vecnormalize.pkl", "policy.npz")):
        d = folder / "models" / name
        d.mkdir(parents=True, exist_ok=True)
        for f in files:
            if (src / f).exists():
                shutil.copy(src / f, d / f)
        made[name] = d
        return d

    d = copy("empty-zip", ("config.yml",))
    (d / "model.zip").write_bytes(b"")
    d = copy("config-list", ("model.zip",))
    (d / "config.yml").write_text("- a\n- b\n")
    d = copy("config-bad-yaml", ("model.zip",))
    (d / "config.yml").write_text("algo: [ppo\n")
    d = copy("config-hp-list", ("model.zip",))
    (d / "config.yml").write_text("algo: ppo\nhyperparams: [1, 2]\n")
    d = copy("damaged-npz")
    (d / "policy.npz").write_bytes((src / "policy.npz").read_bytes()[:300])
    d = copy("pickled-npz")
    import numpy as np

    np.savez(d / "policy.npz", meta=np.array([{"format": 1}], dtype=object))
    copy(
        "foreign-pickle", ("model.zip", "config.yml", "vecnormalize.pkl")
    )  # no policy.npz: SB3 (a pickle) from outside
    d = copy("step-1e-12", ("model.zip", "policy.npz", "vecnormalize.pkl"))
    (d / "config.yml").write_text((src / "config.yml").read_text() + "\n")
    import yaml

    cfg = yaml.safe_load((src / "config.yml").read_text()) or {}
    cfg.setdefault("hyperparams", {})["env_kwargs"] = {"integrator": "RK4", "step": 1e-12}
    (d / "config.yml").write_text(yaml.safe_dump(cfg))
    d = copy("dt-1e6", ("model.zip", "policy.npz", "vecnormalize.pkl"))
    cfg["hyperparams"]["env_kwargs"] = {"dt": 1e6}
    (d / "config.yml").write_text(yaml.safe_dump(cfg))
    (folder / "models" / "not-a-folder").write_text("x")
    made["not-a-folder"] = folder / "models" / "not-a-folder"
    made["missing"] = folder / "models" / "missing"
    return made


# ------------------------------------------------------------------------------------------ cases
def cli_cases(folder: Path) -> list[Case]:
    folder.mkdir(parents=True, exist_ok=True)
    tmp = str(folder)
    cases: list[Case] = []
    for prefix, flag in COUNT_FLAGS:
        pre = [x.replace("{tmp}", tmp) for x in prefix]
        for text in HUGE + NOT_COUNTS:
            cases.append(Case("cli", f"{' '.join(prefix[:2])} {flag} {text[:12]}", "refuse", [*pre, flag, text]))
    for prefix, flag, values in FLOAT_FLAGS:
        pre = [x.replace("{tmp}", tmp) for x in prefix]
        for text in values:
            cases.append(Case("cli", f"{' '.join(prefix[:2])} {flag} {text}", "refuse", [*pre, flag, text]))
    # the product owner's reports
    cases += [
        Case("cli", "bench env --batch 1e9 (int)", "refuse", ["bench", "env", "--batch", "1000000000"]),
        Case(
            "cli", "negative -2e0 is a value", "ok", ["ellipses", "--s3", "-2e0", "--p-theta", "-1E+0", "--grid", "10"]
        ),
        Case(
            "cli",
            "negative -.5 is a value",
            "ok",
            ["ellipses", "--s3", "-.5", "--p-theta", "-1", "--grid", "10", "--json"],
        ),
        Case(
            "cli",
            "simulate RK4 step 1e-6 t_end 1e6 stops at the budget",
            "fail",
            ["simulate", "--scene", "default", "--method", "RK4", "--step", "1e-6", "--t-end", "1e6"],
        ),
        Case(
            "cli",
            "DOP853-numba 1 s budget",
            "fail",
            ["simulate", "--scene", "default", "--t-end", "1e6", "--max-seconds", "1", "--samples", "3"],
        ),
        Case(
            "cli",
            "DOP853-numba 1 s budget with R",
            "fail",
            [
                "simulate",
                "--scene",
                "default",
                "--t-end",
                "1e6",
                "--max-seconds",
                "1",
                "--samples",
                "3",
                "--with-rotation",
            ],
        ),
        Case(
            "cli",
            "RK4 predicted past 0.3 s",
            "fail",
            [
                "simulate",
                "--scene",
                "default",
                "--t-end",
                "4e4",
                "--method",
                "RK4",
                "--step",
                "0.01",
                "--max-seconds",
                "0.3",
                "--samples",
                "3",
            ],
        ),
    ]
    for name, path in _trajectories(folder).items():
        cases.append(
            Case("cli", f"invariants {name}", "refuse", ["invariants", str(path), "--json", "--scene", "default"])
        )
        cases.append(
            Case(
                "cli",
                f"invariants {name} (no body)",
                "refuse" if name not in ("lambda_eq_mu", "mu_eq_lambda_once") else "clean",
                ["invariants", str(path), "--json"],
            )
        )
    for kind in ("directory", "corrupt", "garbage", "foreign"):
        sw = folder / f"sweep-{kind}"
        _bad_sqlite(sw / "results.sqlite", kind)
        cases.append(
            Case(
                "cli",
                f"sweep on a {kind} database",
                "refuse",
                ["sweep", "stability-map", "--grid", "4", "--workers", "0", "--no-progress", "--out", str(sw)],
            )
        )
        sv = folder / f"serve-{kind}"
        _bad_sqlite(sv / "jobs.sqlite3", kind)
        cases.append(
            Case("cli", f"serve on a {kind} database", "refuse", ["serve", "--data-dir", str(sv), "--port", "0"])
        )
        db = folder / f"optuna-{kind}.sqlite3"
        _bad_sqlite(db, kind)
        cases.append(
            Case(
                "cli",
                f"tune on a {kind} storage",
                "refuse",
                [
                    "tune",
                    "--algo",
                    "ppo",
                    "--trials",
                    "1",
                    "--storage",
                    f"sqlite:///{db}",
                    "--out",
                    str(folder / "tune"),
                ],
            )
        )
    import socket

    held = socket.socket()  # a port in use for the whole run: serve must refuse it (exit 2), not exit 3
    held.bind(("127.0.0.1", 0))
    held.listen()
    _HELD.append(held)
    cases.append(
        Case(
            "cli",
            "serve on a port in use",
            "refuse",
            ["serve", "--data-dir", str(folder / "serve-ok"), "--port", str(held.getsockname()[1])],
        )
    )
    cases.append(
        Case(
            "cli",
            "serve on an unknown host",
            "refuse",
            ["serve", "--data-dir", str(folder / "serve-ok"), "--host", "no-such-host.invalid", "--port", "0"],
        )
    )
    (folder / "a-file").write_text("x")
    cases.append(
        Case(
            "cli",
            "sweep --out is a file",
            "refuse",
            ["sweep", "stability-map", "--grid", "4", "--workers", "0", "--out", str(folder / "a-file")],
        )
    )
    cases.append(
        Case(
            "cli",
            "serve --data-dir is a file",
            "refuse",
            ["serve", "--data-dir", str(folder / "a-file"), "--port", "0"],
        )
    )
    models = _model_folders(folder)
    for name, path in models.items():
        for cmd in (
            ["evaluate", str(path), "--episodes", "1", "--no-baselines", "--json"],
            ["demo", "--model", str(path), "--out", ""],
            ["record", "--agent", str(path), "--out", str(folder / f"agent-{name}.rrd")],
            ["export-policy", str(path)],
        ):
            if cmd[0] in ("demo", "record", "export-policy") and name not in (
                "empty-zip",
                "config-list",
                "damaged-npz",
                "foreign-pickle",
                "missing",
            ):
                continue
            cases.append(Case("cli", f"{cmd[0]} {name}", "refuse", cmd))
    cases.append(
        Case(
            "cli",
            "evaluate empty-zip --trust",
            "refuse",
            ["evaluate", str(models["empty-zip"]), "--trust", "--episodes", "1", "--no-baselines"],
        )
    )
    cases.append(
        Case(
            "cli",
            "train --resume from an untrusted folder",
            "refuse",
            ["train", "--algo", "ppo", "--resume", "--out", str(models["foreign-pickle"])],
        )
    )
    return cases


def api_cases(folder: Path) -> list[Case]:
    import gymnasium as gym

    import flatbody_env  # noqa: F401 - registers the env ids
    from flatbody_env.simulation import simulate

    def env_step(**kw):
        def call():
            env = gym.make("FlatBody-v0", **kw)
            env.reset(seed=0)
            obs, reward, term, trunc, info = env.step(env.action_space.sample() * 0)
            env.close()
            return {"obs": obs, "reward": reward, "t": info["t"]}

        return call

    def vec(**kw):
        def call():
            from flatbody_env.env.vector_env import FlatBodyVectorEnv

            env = FlatBodyVectorEnv(**kw)
            obs, info = env.reset(seed=0)
            return {"obs": obs}

        return call

    def sim(**kw):
        return lambda: {"y": simulate("default", **kw).y}

    folder.mkdir(parents=True, exist_ok=True)
    cases: list[Case] = []
    refuse_env = [
        dict(dt=1e6),
        dict(dt=1e9),
        dict(dt=0.0),
        dict(dt=-1.0),
        dict(dt=math.nan),
        dict(dt=math.inf),
        dict(dt=1e-9),
        dict(dt="0.05"),
        dict(dt=True),
        dict(dt=1e300),
        dict(integrator="RK4", step=1e-12),
        dict(integrator="RK4", step=1e-30),
        dict(integrator="RK4", step=1e-7),
        dict(integrator="RK4", step=-0.01),
        dict(integrator="RK4", step=0.06),
        dict(integrator="RK4", dt=1.0, step=5e-6),
        dict(integrator=123),
        dict(integrator="nope"),
        dict(integrator=None),
        dict(rtol=0.0),
        dict(atol=math.nan),
        dict(torque_limit=1e300),
        dict(force_limit=-1.0),
        dict(momentum_bound=math.inf),
        dict(stretch_bounds=(5,)),
        dict(stretch_bounds="ab"),
        dict(stretch_bounds=(2.0, 1.0)),
        dict(rho_bounds=(0.0, 1e400)),
        dict(gap_min=2.0),
        dict(track_rotation="x"),
        dict(foo=1),
        dict(control=5),
        dict(task=3),
        dict(body=[1]),
    ]
    for kw in refuse_env:
        cases.append(Case("api", f"gym.make {kw}", "refuse", call=env_step(**kw)))
    for kw in [
        dict(num_envs=10**9),
        dict(num_envs=0),
        dict(num_envs=True),
        dict(num_envs=2.5),
        dict(num_envs=2, max_episode_steps=10**12),
        dict(num_envs=2, max_episode_steps=0),
        dict(num_envs=2, dt=1e6),
    ]:
        cases.append(Case("api", f"FlatBodyVectorEnv {kw}", "refuse", call=vec(**kw)))
    # the largest allowed work per env step stays within the per-step budget
    for kw in [
        dict(dt=1.0, integrator="RK4", step=1e-5),
        dict(dt=1.0, rtol=1e-16, atol=1e-16),
        dict(dt=1.0, integrator="DOP853"),
        dict(dt=1e-4),
    ]:
        cases.append(Case("api", f"gym.make {kw} (allowed extreme)", "clean", call=env_step(**kw)))
    for kw in [
        dict(t_end=1.0, method="RK4", step=1e-30),
        dict(t_end=1.0, method="RK4", step=1e-7),
        dict(t_end=1.0, max_wall_time=1e9),
        dict(t_end=1.0, max_wall_time=math.inf),
        dict(t_end=1.0, method="RK4", step=True),
        dict(t_end=1e7),
    ]:
        cases.append(Case("api", f"simulate {kw}", "refuse", call=sim(**kw)))
    cases.append(Case("api", "simulate RK4 1e6/1e-6 (budget)", "fail", call=sim(t_end=1e6, method="RK4", step=1e-6)))
    trajs = _trajectories(folder)
    from analysis.invariants import invariants_along
    from flatbody_env.scene import load_scene

    body = load_scene("default").body
    for name, path in trajs.items():
        cases.append(
            Case("api", f"invariants_along {name}", "refuse", call=lambda p=path: invariants_along(p, body).to_dict())
        )
    from flatbody_env.sweep.store import ResultStore

    for kind in ("directory", "corrupt", "garbage", "foreign"):
        d = folder / f"api-store-{kind}"
        _bad_sqlite(d / "results.sqlite", kind)
        cases.append(Case("api", f"ResultStore {kind}", "refuse", call=lambda d=d: ResultStore(d)))
    from agents.evaluate import Agent
    from agents.numpy_policy import load_policy

    models = _model_folders(folder)
    for name in (
        "empty-zip",
        "config-list",
        "config-bad-yaml",
        "config-hp-list",
        "damaged-npz",
        "pickled-npz",
        "not-a-folder",
        "missing",
    ):
        cases.append(Case("api", f"Agent {name}", "refuse", call=lambda p=models[name]: Agent(p)))
    cases.append(Case("api", "load_policy damaged", "refuse", call=lambda: load_policy(models["damaged-npz"])))
    cases.append(Case("api", "load_policy pickled", "refuse", call=lambda: load_policy(models["pickled-npz"])))
    return cases


# ------------------------------------------------------------------------------------------ runner
class _Timeout(BaseException):
    pass


def _nonfinite(value: Any) -> bool:
    import numpy as np

    if isinstance(value, dict):
        return any(_nonfinite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_nonfinite(v) for v in value)
    if isinstance(value, (float, int, np.ndarray, np.floating)) and not isinstance(value, bool):
        arr = np.asarray(value)
        return arr.dtype.kind in "fc" and not np.all(np.isfinite(arr))
    return False


def run(case: Case) -> dict:
    """Run one case; classify it (module docstring)."""
    if case.kind == "cli":
        r = hostile.run_case(case.argv, case.limit)
        outcome = r["outcome"]
        err = r["err"]
        if outcome == "exit":
            outcome = {0: "ok", 1: "fail", 2: "refuse"}.get(r["code"], "other-exit")
            if "internal error" in err:
                outcome = "traceback"
            if r["code"] == 2 and ("unrecognized arguments" in err or "invalid choice" in err or "required" in err):
                outcome = "misparsed"  # refused, but not for the reason the case tests
        return {
            "name": case.name,
            "expect": case.expect,
            "outcome": outcome,
            "nan": r["nan"],
            "err_lines": r["err_lines"],
            "err": err,
        }
    from flatbody_env.integrators import IntegrationError

    def alarm(signum, frame):
        raise _Timeout

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, case.limit)
    nan = False
    err = ""
    try:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = case.call()
        outcome = "ok"
        nan = _nonfinite(result)
    except _Timeout:
        outcome = "hang"
    except IntegrationError as exc:
        outcome, err = "fail", str(exc)
    except ValueError as exc:
        outcome, err = "refuse", str(exc)
    except OSError as exc:
        outcome, err = "fail", str(exc)
    except BaseException as exc:
        outcome, err = "traceback", f"{type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return {
        "name": case.name,
        "expect": case.expect,
        "outcome": outcome,
        "nan": nan,
        "err_lines": len(err.splitlines()),
        "err": err[-300:],
    }


def bad(row: dict) -> str | None:
    """Why a case's outcome counts against the package (None: it is fine)."""
    if row["outcome"] in ("traceback", "hang", "other-exit", "misparsed"):
        return row["outcome"]
    if row["nan"]:
        return "non-finite output"
    if row["err_lines"] > 3:
        return "long error"
    if row["expect"] == "refuse" and row["outcome"] == "ok":
        return "silent accept"
    if row["expect"] in ("refuse", "fail", "ok") and row["outcome"] != row["expect"]:
        return f"expected {row['expect']}, got {row['outcome']}"
    return None


def tally(rows: list[dict]) -> dict:
    out = {
        "cases": len(rows),
        "cli": sum(r.get("kind") == "cli" for r in rows),
        "api": sum(r.get("kind") == "api" for r in rows),
    }
    for key in ("ok", "fail", "refuse"):
        out[key] = sum(r["outcome"] == key for r in rows)
    reasons = [bad(r) for r in rows]
    out["tracebacks"] = sum(x == "traceback" for x in reasons)
    out["hangs"] = sum(x == "hang" for x in reasons)
    out["silent_accepts"] = sum(x == "silent accept" for x in reasons)
    out["non_finite_outputs"] = sum(x == "non-finite output" for x in reasons)
    out["other_problems"] = (
        sum(x is not None for x in reasons)
        - out["tracebacks"]
        - out["hangs"]
        - out["silent_accepts"]
        - out["non_finite_outputs"]
    )
    return out


def run_all(folder: Path) -> tuple[dict, list[dict]]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    rows = []
    for case in cli_cases(folder / "cli") + api_cases(folder / "api"):
        row = run(case)
        row["kind"] = case.kind
        rows.append(row)
    return tally(rows), rows


if __name__ == "__main__":  # python tests/fuzz/corpus.py [FOLDER]
    import tempfile
    import time

    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="flatbody-corpus-"))
    start = time.perf_counter()
    counts, rows = run_all(folder)
    counts["seconds"] = round(time.perf_counter() - start, 1)
    print(json.dumps(counts, indent=2))
    for r in rows:
        why = bad(r)
        if why:
            print(
                f"{why:>18} | {r['kind']} {r['name'][:70]} | {r['outcome']} | {r['err'].strip()[-220:]}".replace(
                    "\n", " / "
                )
            )
