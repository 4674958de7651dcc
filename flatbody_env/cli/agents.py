"""Sub-commands of the agents layer: ``train``, ``evaluate``, ``demo`` (the README's main job),
``export-policy`` (the numpy policy that ``evaluate`` and ``demo`` run without torch), and the shipped tables the
tasks and the LQR read: ``targets-table``, ``lqr-table``.

Heavy imports (torch, SB3) happen inside the handlers so that ``flatbody --help`` stays fast.
"""

from __future__ import annotations

import json
import sys

from flatbody_env.cli.args import int_at_least
from flatbody_env.physics import validation


def _train_rsl(args) -> int:
    """``train --algo rsl-ppo``: rsl_rl's PPO on the torch vector env (agents/rsl.py)."""
    from agents.rsl import ALGO, train_rsl

    if args.study is not None or args.resume or args.hyperparams_file or args.trained_agent:
        raise ValueError(
            "--algo rsl-ppo: --study, --resume, --trained-agent and --hyperparams-file are SB3-only (give --hyperparams KEY=VALUE)"
        )
    command = (
        ["flatbody", *sys.argv[1:]]
        if sys.argv and sys.argv[0].endswith(("flatbody", "__main__.py", "main.py"))
        else None
    )
    out = args.out or f"runs/{ALGO}-{args.env}-seed{args.seed}"
    result = train_rsl(  # trusts the folder once its first file is written (agents.numpy_policy.remember_run)
        out,
        seed=args.seed,
        n_timesteps=args.n_timesteps,
        n_envs=args.n_envs,
        device=args.device,
        overrides=args.hyperparams or [],
        env_id=args.env,
        threads=args.threads,
        progress=not args.no_progress,
        command=command,
        force=args.force,
        checkpoint_freq=args.checkpoint_freq,
        keep_checkpoints=args.keep_checkpoints,
    )
    print(f"trained {ALGO} for {result.timesteps} steps in {result.wall_time_s:.0f} s; saved in {result.out}")
    return 0


def _trusting(handler):
    """Run ``handler`` with loading a pickle (SB3 model.zip, vecnormalize.pkl, checkpoints) allowed only
    from a trusted folder, unless ``--trust`` was given (docs/reliability.md, Trust model)."""
    import functools

    @functools.wraps(handler)
    def run(args) -> int:
        from agents.numpy_policy import trust_policy

        with trust_policy(not getattr(args, "trust", False)):
            return handler(args)

    return run


@_trusting
def _train(args) -> int:
    if args.algo == "rsl-ppo":
        return _train_rsl(args)
    if args.device != "cpu":
        raise ValueError("--device: only rsl-ppo trains on another device than the CPU")
    from agents.train import train

    if args.study is not None:  # retrain a tuned trial: its hyperparameters become overrides
        from agents.tune import DEFAULT_STORAGE, trial_overrides

        if args.trial_id is None:
            raise ValueError("--trial-id: required with --study (a trial number of the study)")
        algo, tuned, hp_file, n_envs = trial_overrides(args.study, args.storage or DEFAULT_STORAGE, args.trial_id)
        if args.algo not in (None, algo):
            raise ValueError(f"--algo: study {args.study!r} tuned {algo}, not {args.algo}")
        args.algo, args.hyperparams = algo, [*tuned, *(args.hyperparams or [])]
        args.hyperparams_file = args.hyperparams_file or hp_file
        args.n_envs = args.n_envs or n_envs
    elif args.algo is None:
        raise ValueError("--algo: required (ppo or sac), or give --study NAME --trial-id K")
    command = (
        ["flatbody", *sys.argv[1:]]
        if sys.argv and sys.argv[0].endswith(("flatbody", "__main__.py", "main.py"))
        else None
    )
    out = args.out or f"runs/{args.algo}-{args.env}-seed{args.seed}"
    if args.trained_agent is not None and args.resume:
        raise ValueError("--trained-agent: not with --resume (a resumed run continues its own model)")
    # train() checks the trust of --resume's checkpoints and --trained-agent's model before it loads a pickle, and
    # trusts --out once the run's first file is written there (never on a refusal before it)
    result = train(
        args.algo,
        out,
        seed=args.seed,
        n_timesteps=args.n_timesteps,
        n_envs=args.n_envs,
        overrides=args.hyperparams or [],
        hyperparams_file=args.hyperparams_file,
        env_id=args.env,
        resume=args.resume,
        checkpoint_freq=args.checkpoint_freq,
        keep_checkpoints=args.keep_checkpoints,
        threads=args.threads,
        progress=not args.no_progress,
        command=command,
        force=args.force,
        trained_agent=args.trained_agent,
    )
    note = f" (resumed from {result.resumed_from} steps)" if result.resumed_from is not None else ""
    print(
        f"trained {args.algo} for {result.timesteps} steps in {result.wall_time_s:.0f} s{note}; saved in {result.out}"
    )
    _export_after_training(result.out)
    return 0


def _export_after_training(out) -> None:
    """Write ``policy.npz`` beside the new model, so that evaluate/demo/record load this run without
    unpickling anything (docs/reliability.md, Trust model); a policy the numpy evaluator cannot run
    is reported on stderr and left to SB3."""
    from agents.numpy_policy import export_policy

    try:
        export_policy(out)
    except ValueError as exc:
        sys.stderr.write(
            f"flatbody: no policy.npz exported ({' '.join(str(exc).split())[:200]}); evaluate uses Stable-Baselines3\n"
        )


@_trusting
def _evaluate(args) -> int:
    from agents.evaluate import evaluate_all, format_table

    if args.env is not None or args.out_dir or args.docs:
        return _evaluate_tasks(args)
    report = evaluate_all(
        args.model,
        episodes=args.episodes,
        seed=args.seed,
        baselines=not args.no_baselines,
        progress=not args.json,
        backend=args.backend,
    )
    if args.out:
        from flatbody_env.output import atomic_write

        atomic_write(args.out, json.dumps(report, indent=2) + "\n")
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_table(report))
    return 0


def _evaluate_tasks(args) -> int:
    """``evaluate --env ID|all``: the reference report of each task (agents.reference), saved with --out-dir, the docs block with --docs."""
    from agents.evaluate import evaluate_task, format_table
    from agents.reference import REFERENCE_DIR, save_report, update_docs
    from flatbody_env.env.registration import V1_IDS, task_spec

    if args.env is None and not args.out_dir:  # --docs alone: the table from the saved reports, no evaluation
        update_docs(args.docs, REFERENCE_DIR)
        print(f"updated the table in {args.docs} from {REFERENCE_DIR}")
        return 0
    ids = V1_IDS if args.env == "all" else (task_spec(args.env or "FlatBody-v1").env_id,)
    if args.model is not None and len(ids) > 1:
        raise ValueError("--env: give one task id with MODEL (all evaluates the shipped agents)")
    reports = []
    for env_id in ids:
        report = evaluate_task(
            env_id,
            episodes=args.episodes,
            seed=args.seed,
            model=args.model,
            baselines=not args.no_baselines,
            progress=not args.json,
            backend=args.backend,
        )
        reports.append(report)
        if args.out_dir:
            print(f"wrote {save_report(report, args.out_dir)}", file=sys.stderr)
    if args.docs:
        update_docs(args.docs, args.out_dir or REFERENCE_DIR)
        print(f"updated the table in {args.docs}", file=sys.stderr)
    if args.out:
        from flatbody_env.output import atomic_write

        atomic_write(args.out, json.dumps(reports[0] if len(reports) == 1 else reports, indent=2) + "\n")
    if args.json:
        brief = [{k: v for k, v in r.items() if k not in ("policies", "targets")} for r in reports]
        print(json.dumps(brief[0] if len(brief) == 1 else brief, indent=2))
    else:
        print("\n\n".join(format_table(r) for r in reports))
    return 0


@_trusting
def _demo(args) -> int:
    import shlex

    from agents.demo import run_demo

    if args.docs:  # checked before the episode runs
        from flatbody_env.output import check_output_path

        if not check_output_path("--docs", args.docs, (".md",)).is_file():
            raise ValueError(
                f"--docs: {args.docs[:60]!r} does not exist (a Markdown page with <!-- demo:transcript --> markers)"
            )
    if args.out:  # rerun's writer cannot stop cleanly on a full disk: refuse up front what it cannot hold
        from flatbody_env.cli.record import check_space

        check_space(args.out, 1000)
    # the transcript's command line: the options given, less --docs
    given = [
        ("--model", args.model, None),
        ("--seed", args.seed, 7),
        ("--out", args.out, "demo.rrd"),
        ("--backend", args.backend, "auto"),
    ]
    command = shlex.join(
        ["flatbody", "demo", *(x for flag, value, default in given if value != default for x in (flag, str(value)))]
    )
    return run_demo(
        model=args.model, seed=args.seed, out=args.out, backend=args.backend, docs=args.docs or None, command=command
    )


@_trusting
def _export_policy(args) -> int:
    from agents.numpy_policy import export_policy

    path = export_policy(args.model)
    print(f"wrote {path}")
    return 0


def _lqr_table(args) -> int:
    from agents.heuristic import GAIN_TABLE_PATH, build_gain_table, save_gain_table

    from agents.heuristic import GAIN_GRID_LAMBDA, GAIN_GRID_W

    table = build_gain_table(
        workers=args.workers, grid_lambda=(*GAIN_GRID_LAMBDA[:2], args.n_lambda), grid_w=(*GAIN_GRID_W[:2], args.n_w)
    )
    out = args.out or GAIN_TABLE_PATH
    save_gain_table(table, out)
    print(f"wrote {out}: LQR gains at {table['K'].shape[0] * table['K'].shape[1] * table['K'].shape[2]} target shapes")
    return 0


def _targets_table(args) -> int:
    from pathlib import Path

    import numpy as np

    from flatbody_env.env.targets import GRID_ASPECT, GRID_LAMBDA, TABLE_PATH, build_table

    table = build_table(
        grid_lambda=(*GRID_LAMBDA[:2], args.n_lambda),
        grid_aspect=(*GRID_ASPECT[:2], args.n_aspect),
        workers=args.workers,
        progress=not args.no_progress,
    )
    out = Path(args.out) if args.out else TABLE_PATH
    table.save(out)
    edge = int(np.isfinite(table.edge_lo).sum())
    print(
        f"wrote {out}: {table.rate.shape[1]} x {table.rate.shape[0]} shapes (lambda x aspect), {edge} edge cells, "
        f"largest interpolation margin {float(np.max(table.margin[np.isfinite(table.margin)])):.2e} 1/s"
    )
    return 0


def register(sub) -> None:
    from agents.train import ALGOS, ENV_ID

    p = sub.add_parser("train", help="train an agent (SB3 PPO or SAC, or rsl_rl's PPO: rsl-ppo) on FlatBody-v0")
    p.add_argument(
        "--algo",
        choices=(*ALGOS, "rsl-ppo"),
        help="algorithm (required unless --study); rsl-ppo: rsl_rl's PPO on the torch vector env",
    )
    p.add_argument("--env", default=ENV_ID, help=f"environment id (default {ENV_ID})")
    p.add_argument(
        "--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=0, help="random seed (default 0)"
    )
    p.add_argument(
        "--n-timesteps",
        type=int_at_least("n_timesteps", 1, validation.MAX_TIMESTEPS),
        default=None,
        metavar="N",
        help="total environment steps (default: the YAML's)",
    )
    p.add_argument(
        "--n-envs",
        "--num-envs",
        dest="n_envs",
        type=int_at_least("n_envs", 1, validation.MAX_BATCH),
        default=None,
        metavar="N",
        help="parallel bodies (default: the YAML's)",
    )
    p.add_argument(
        "--hyperparams", nargs="*", metavar="KEY=VALUE", help="override YAML entries (values parsed as YAML)"
    )
    p.add_argument("--hyperparams-file", metavar="FILE", help="YAML file (default: agents/hyperparams/ALGO.yml)")
    p.add_argument("--out", metavar="DIR", help="output folder (default runs/ALGO-ENV-seedS)")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in DIR/checkpoints")
    p.add_argument(
        "--trained-agent",
        metavar="RUN",
        help="fine-tune: start from this run folder's model.zip and vecnormalize.pkl "
        "(this run's hyperparameters; SB3 algorithms)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="train into DIR even if it holds a run or is the shipped agent (overwrites it)",
    )
    p.add_argument(
        "--checkpoint-freq",
        type=int_at_least("checkpoint_freq", 0, validation.MAX_TIMESTEPS),
        default=50_000,
        metavar="N",
        help="steps between checkpoints (0: none; default 50000)",
    )
    p.add_argument("--keep-checkpoints", action="store_true", help="keep DIR/checkpoints after a completed run")
    p.add_argument(
        "--threads",
        type=int_at_least("threads", 1, validation.MAX_WORKERS),
        default=1,
        help="torch threads (default 1)",
    )
    p.add_argument(
        "--device", choices=("cpu", "cuda"), default="cpu", help="torch device of env and policy (rsl-ppo; default cpu)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--study",
        metavar="NAME",
        help="retrain a trial of this Optuna study ('flatbody tune') with its hyperparameters",
    )
    p.add_argument(
        "--trial-id",
        type=int_at_least("trial_id", 0, validation.MAX_COUNT),
        default=None,
        metavar="K",
        help="with --study: the trial number",
    )
    p.add_argument(
        "--storage",
        metavar="URL",
        help="with --study: journal file or database URL (default sqlite:///runs/tune/optuna.sqlite3, with a heartbeat)",
    )
    p.add_argument(
        "--trust",
        action="store_true",
        help="allow unpickling a model from outside the shipped agent and your own runs (pickles can run code; docs/reliability.md)",
    )
    p.set_defaults(handler=_train)

    p = sub.add_parser(
        "evaluate", help="evaluate an agent and the baselines (zero, random, heuristic) over seeded episodes"
    )
    p.add_argument(
        "model", nargs="?", default=None, metavar="MODEL", help="model folder or model.zip (default: the shipped agent)"
    )
    p.add_argument(
        "--episodes",
        type=int_at_least("episodes", 1, validation.MAX_EPISODES),
        default=100,
        metavar="N",
        help="episodes (default 100)",
    )
    from agents.evaluate import EVAL_SEED

    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=EVAL_SEED,
        metavar="S",
        help=f"episode i is reset with seed S + i (default {EVAL_SEED})",
    )
    p.add_argument("--no-baselines", action="store_true", help="evaluate the agent only")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--out", metavar="FILE", help="also write the JSON report here")
    p.add_argument(
        "--backend",
        choices=("auto", "numpy", "sb3"),
        default="auto",
        help="policy evaluation: the exported numpy policy, SB3 itself, or auto (numpy when current; default)",
    )
    p.add_argument(
        "--env",
        default=None,
        metavar="ID",
        help="task id (docs/tasks.md) or 'all': the baselines, the task's shipped agents (agents/models/ALGO-ID/) and target features",
    )
    p.add_argument(
        "--out-dir",
        default="",
        metavar="DIR",
        help="with --env: save each task's report as DIR/ID.json (the reference table)",
    )
    p.add_argument(
        "--docs",
        default="",
        metavar="FILE.md",
        help="regenerate the table between <!-- bench:tasks --> markers in FILE.md from the saved reports (--out-dir, default the shipped ones)",
    )
    p.add_argument(
        "--trust",
        action="store_true",
        help="allow unpickling a model from outside the shipped agent and your own runs (pickles can run code; docs/reliability.md)",
    )
    p.set_defaults(handler=_evaluate)

    p = sub.add_parser("demo", help="the main job: the shipped agent steers the body onto a stationary ellipse")
    p.add_argument(
        "--model", default=None, metavar="MODEL", help="model folder or model.zip (default: the shipped agent)"
    )
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=7,
        help="seed of the target and the initial state (default 7)",
    )
    p.add_argument(
        "--out", default="demo.rrd", metavar="FILE.rrd", help="rerun recording to write (default demo.rrd; '' for none)"
    )
    p.add_argument(
        "--backend",
        choices=("auto", "numpy", "sb3"),
        default="auto",
        help="policy evaluation: the exported numpy policy, SB3 itself, or auto (numpy when current; default)",
    )
    p.add_argument(
        "--docs",
        default="",
        metavar="FILE.md",
        help="also regenerate the transcript between <!-- demo:transcript --> markers in FILE.md",
    )
    p.add_argument(
        "--trust",
        action="store_true",
        help="allow unpickling a model from outside the shipped agent and your own runs (pickles can run code; docs/reliability.md)",
    )
    p.set_defaults(handler=_demo)
    p = sub.add_parser(
        "targets-table", help="regenerate the task's settling-rate table (default body, limits and controls)"
    )
    p.add_argument("--out", default="", help="where to write it (default: the package's own table file)")
    p.add_argument(
        "--n-lambda", type=int_at_least("n_lambda", 2, 2001), default=71, help="grid nodes in lambda* (shipped: 71)"
    )
    p.add_argument(
        "--n-aspect", type=int_at_least("n_aspect", 2, 2001), default=81, help="grid nodes in lambda*/mu* (shipped: 81)"
    )
    p.add_argument("--workers", type=int_at_least("workers", 1, validation.MAX_WORKERS), default=2, help="processes")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_targets_table)

    p = sub.add_parser(
        "lqr-table", help="regenerate the LQR controller's gain table (default body, limits, controls, weights)"
    )
    p.add_argument("--out", default="", help="where to write it (default: the package's own table file)")
    p.add_argument(
        "--n-lambda", type=int_at_least("n_lambda", 2, 2001), default=36, help="grid nodes in lambda* (shipped: 36)"
    )
    p.add_argument(
        "--n-w", type=int_at_least("n_w", 2, 2001), default=41, help="grid nodes in w = 1/(lambda* mu*) (shipped: 41)"
    )
    p.add_argument("--workers", type=int_at_least("workers", 1, validation.MAX_WORKERS), default=2, help="processes")
    p.set_defaults(handler=_lqr_table)

    p = sub.add_parser(
        "export-policy",
        help="export a trained agent's policy to numpy (policy.npz beside model.zip) for torch-free evaluate/demo",
    )
    p.add_argument(
        "model", nargs="?", default=None, metavar="MODEL", help="model folder or model.zip (default: the shipped agent)"
    )
    p.add_argument(
        "--trust",
        action="store_true",
        help="allow unpickling a model from outside the shipped agent and your own runs (pickles can run code; docs/reliability.md)",
    )
    p.set_defaults(handler=_export_policy)
