"""Sub-commands of the agents layer: ``train`` (SB3's PPO, SAC, TD3 and rsl_rl's PPO on any task; ``--resume``,
``--config``), ``curriculum`` and ``imitate plan|clone`` (the prior track), ``evaluate``, ``demo`` (the README's main
job), ``export-policy`` (the numpy policy that ``evaluate`` and ``demo`` run without torch).

Heavy imports (torch, SB3) happen inside the handlers so that ``flatbody --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import sys

from flatbody_env.cli.args import int_at_least, name_list, number, number_list, output_dir, output_file, seed_range
from flatbody_env.physics import validation


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


def _command() -> list[str] | None:
    """The command line of this ``flatbody`` run as it was typed (for run.json), None outside the ``flatbody`` entry."""
    if sys.argv and sys.argv[0].endswith(("flatbody", "__main__.py", "main.py")):
        return ["flatbody", *sys.argv[1:]]
    return None


def _refuse_with(flag: str, given, why: str) -> None:
    validation.requirement(flag, given, not given, f"be left out {why}")


def _run_config(args):
    """(config, folder, resume) of ``flatbody train``: a run to continue (``--resume``), a configuration to train again
    (``--config``) or a new run; every refusal before anything is written."""
    from agents.config import SB3_ALGOS, RunConfig, apply_overrides, check_device, check_hyperparams, resolve
    from agents.runs import RunFolder
    from agents.train import check_resumed

    check_device(args.device, "--device")  # cuda without a GPU: one line naming --device
    if args.device != "cpu" and args.algo in SB3_ALGOS:
        validation.requirement("--device", args.device, False, "be cpu for the SB3 algorithms (rsl-ppo trains on cuda)")
    if args.resume:
        for flag, given in (
            ("--config", args.config),
            ("--study", args.study),
            ("--hyperparams-file", args.hyperparams_file),
            ("--trained-agent", args.trained_agent),
        ):
            _refuse_with(flag, given, "with --resume (the run's config.yml holds it)")
        if args.out is None and (args.algo is None or args.env is None):
            raise ValueError("--out: required with --resume (the run's folder), or give --algo and --env")
        folder = RunFolder.existing(args.out or f"runs/{args.algo}-{args.env}-seed0")
        config = folder.config()
        check_resumed(config, folder, algo=args.algo, env_id=args.env, flag="--")
        _same_settings(args, config)
        if args.device != config.device:
            validation.requirement("--device", args.device, False, f"be {config.device}, the device the run trains on")
        if args.n_timesteps is not None:  # a larger budget: continue beyond the planned end
            hp = {**config.hyperparams, "n_timesteps": args.n_timesteps}
            config = config.replace(hyperparams=check_hyperparams(config.algo, hp, config.env_id))
        return config, folder, True
    if args.config:
        for flag, given in (("--study", args.study), ("--hyperparams-file", args.hyperparams_file)):
            _refuse_with(flag, given, "with --config (the configuration holds the hyperparameters)")
        config = RunConfig.read(args.config, where="--config")
        if config.imitation is not None:
            again = (
                f"flatbody imitate distill --config {args.config[:80]} repeats it"
                if config.imitation.get("method") == "distill"
                else "flatbody imitate clone made it (run.json beside it holds the command)"
            )
            raise ValueError(
                f"--config: {args.config[:80]!r} is a policy imitated from plans (prior.imitation): {again}"
            )
        for flag, given, recorded in (("--algo", args.algo, config.algo), ("--env", args.env, config.env_id)):
            validation.requirement(
                flag, given, given in (None, recorded), f"be {recorded} as in {args.config[:80]} (or left out)"
            )
        folder = RunFolder.new(args.out or f"runs/{config.algo}-{config.env_id}-seed{config.seed}", force=args.force)
        hp = apply_overrides(config.hyperparams, args.hyperparams or [])
        if args.n_timesteps is not None:
            hp["n_timesteps"] = args.n_timesteps
        if args.n_envs is not None:
            hp["n_envs"] = args.n_envs
        config = config.replace(
            seed=config.seed if args.seed is None else args.seed,
            device=args.device if args.device != "cpu" else config.device,
            hyperparams=check_hyperparams(config.algo, hp, config.env_id),
            trained_agent=args.trained_agent or config.trained_agent,
            source={**config.source, "config": args.config, "overrides": list(args.hyperparams or [])},
        )
        check_device(config.device, "--device")
        return config, folder, False
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
        raise ValueError("--algo: required (ppo, sac, td3 or rsl-ppo), or give --config, --resume or --study")
    from agents.config import DEFAULT_ENV_ID

    env_id = args.env or DEFAULT_ENV_ID
    seed = 0 if args.seed is None else args.seed
    folder = RunFolder.new(args.out or f"runs/{args.algo}-{env_id}-seed{seed}", force=args.force)
    config = resolve(
        args.algo,
        env_id,
        seed=seed,
        n_timesteps=args.n_timesteps,
        n_envs=args.n_envs,
        overrides=args.hyperparams or [],
        hyperparams_file=args.hyperparams_file,
        device=args.device,
        trained_agent=args.trained_agent,
    )
    return config, folder, False


def _same_settings(args, config) -> None:
    """With ``--resume``, a seed, ``--n-envs`` or ``--hyperparams`` may be given only as the run's config.yml has them
    (the run continues as it began); anything else is refused naming the flag."""
    from agents.config import apply_overrides, check_hyperparams

    if args.seed is not None:
        validation.requirement("--seed", args.seed, args.seed == config.seed, f"be {config.seed}, the run's seed")
    hp = apply_overrides(config.hyperparams, args.hyperparams or [])
    if args.n_envs is not None:
        hp["n_envs"] = args.n_envs
    hp = check_hyperparams(config.algo, {**hp, "n_timesteps": config.n_timesteps}, config.env_id)
    changed = sorted(k for k in set(hp) | set(config.hyperparams) if hp.get(k) != config.hyperparams.get(k))
    if changed:
        flag = "--n-envs" if changed == ["n_envs"] else "--hyperparams"
        validation.requirement(
            flag,
            ", ".join(changed),
            False,
            "agree with the run's config.yml with --resume (a resumed run continues as it began; give a new --out)",
        )


def _evaluations(args, config):
    """``--eval-freq``'s evaluations of a run (:class:`agents.evaluate.HeldOutEvaluations`), or None."""
    for name in ("eval_seed", "eval_episodes"):
        if getattr(args, name) is not None and not args.eval_freq:
            raise ValueError(f"{name}: give --eval-freq N too (the evaluations along the run)")
    if not args.eval_freq:
        return None
    from agents.evaluate import HeldOutEvaluations

    # the seed and episodes given; the others are HeldOutEvaluations's defaults (the table's)
    given = {k: v for k, v in (("seed", args.eval_seed), ("episodes", args.eval_episodes)) if v is not None}
    return HeldOutEvaluations.every(
        args.eval_freq, config.n_timesteps, config.env_id, env_kwargs=config.env_kwargs, **given
    )


@_trusting
def _train(args) -> int:
    from agents.train import train_config

    config, folder, resume = _run_config(args)
    # train_config checks the trust of --resume's checkpoints and --trained-agent's model before it loads a pickle, and
    # trusts the folder once the run's first file (config.yml) is written there (never on a refusal before it)
    result = train_config(
        config,
        folder,
        resume=resume,
        checkpoint_freq=args.checkpoint_freq,
        keep_checkpoints=args.keep_checkpoints,
        threads=args.threads,
        progress=not args.no_progress,
        command=_command(),
        force=args.force,
        evaluations=_evaluations(args, config),
    )
    note = f" (resumed from {result.resumed_from} steps)" if result.resumed_from is not None else ""
    print(
        f"trained {config.algo} on {config.env_id} for {result.timesteps} steps in {result.wall_time_s:.0f} s{note}; "
        f"saved in {result.out}"
    )
    return 0


@_trusting
def _curriculum(args) -> int:
    """``flatbody curriculum``: ``flatbody train`` of an SB3 algorithm with a curriculum over one task keyword."""
    from agents.config import check_device, resolve
    from agents.runs import RunFolder
    from agents.train import train_config

    check_device(args.device, "--device")
    if args.device != "cpu":
        validation.requirement("--device", args.device, False, "be cpu (the curriculum trains SB3 algorithms)")
    env_id = args.env
    folder = RunFolder.new(args.out or f"runs/{args.algo}-{env_id}-curriculum-seed{args.seed}", force=args.force)
    train_kw = {}
    for item in args.train_env_kwargs:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--train-env-kwargs: expected KEY=VALUE, got {item[:60]!r}")
        train_kw[key] = validation.parse_yaml(f"--train-env-kwargs.{key[:60]}", text)
    from agents.evaluate import env_kwargs_for
    from flatbody_env.env.core import configure

    try:  # the training environments' keywords, checked now (not at the first stage's switch)
        configure(**env_kwargs_for(env_id, {**train_kw, args.key: args.stages[-1]}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--train-env-kwargs: {' '.join(str(exc).split())[:200]}") from None
    curriculum = {
        "key": args.key,
        "stages": args.stages,
        "advance_at": args.advance_at,
        "min_stage_steps": args.min_stage_steps,
        "max_stage_steps": args.max_stage_steps,
        "window": args.window,
        "train_env_kwargs": train_kw,
        "log_std_per_action": args.log_std_per_action,
    }
    config = resolve(
        args.algo,
        env_id,
        seed=args.seed,
        n_timesteps=args.n_timesteps,
        n_envs=args.n_envs,
        overrides=args.hyperparams or [],
        trained_agent=args.trained_agent,
        curriculum=curriculum,
    )
    result = train_config(
        config,
        folder,
        checkpoint_freq=args.checkpoint_freq,
        keep_checkpoints=args.keep_checkpoints,
        threads=args.threads,
        progress=not args.no_progress,
        command=_command(),
        force=args.force,
        evaluations=_evaluations(args, config),
    )
    stages = (folder.config().curriculum or {}).get("history") or []
    print(
        f"trained {config.algo} on {env_id} for {result.timesteps} steps in {result.wall_time_s:.0f} s through "
        f"{len(stages)} of {len(args.stages)} stages; saved in {result.out}"
    )
    return 0


@_trusting
def _imitate(args) -> int:
    """``flatbody imitate plan|clone`` (agents/imitation.py)."""
    import numpy as np

    from agents.imitation import Plans, PlanSettings, _residual_agent, clone, plan

    if args.step == "distill":
        return _distill(args)
    if args.step == "plan":
        settings = PlanSettings(
            knots=args.knots,
            samples=args.samples,
            iterations=args.iterations,
            elite=args.elite,
            init_std=args.init_std,
            reach=args.reach,
            chunk=args.chunk,
            seed=args.seed,
        )
        lo, hi = args.seeds
        plans = plan(args.model, range(lo, hi), settings, on_policy=args.on_policy, progress=not args.no_progress)
        plans.save(args.out)
        tol = _residual_agent(args.model).residual_action.task.success_tolerance
        print(
            f"planned {plans.seeds.size} episodes: {np.mean(plans.final_distance <= tol):.0%} end within {tol:g}; "
            f"median final distance {np.median(plans.final_distance):.4f}; wrote {args.out}"
        )
        return 0
    plans = Plans.load(args.plans[0])
    for f in args.plans[1:]:
        plans = plans + Plans.load(f)
    res = clone(
        plans,
        args.model,
        args.out,
        epochs=args.epochs,
        seed=args.seed,
        progress=not args.no_progress,
        force=args.force,
        command=_command(),
        plans_files=list(args.plans),
    )
    print(
        f"cloned {res['plans']} plans ({res['pairs']} steps; replayed {res['replayed_success']:.0%} within the "
        f"tolerance): squared error {res['mse_start']:.4f} -> {res['mse_end']:.4f}; wrote {args.out}"
    )
    return 0


def _distill(args) -> int:
    """``flatbody imitate distill``: every flag checked, then :func:`agents.imitation.distill`."""
    from dataclasses import asdict

    from agents.config import RunConfig
    from agents.imitation import DistillSettings, distill, distill_config, distill_settings_of
    from agents.planner import parse_overrides

    given = {k: getattr(args, k) for k in ("rounds", "epochs", "batch_size", "learning_rate")}
    planner = parse_overrides(args.planner, "--planner") if args.planner else None
    if args.config:
        for flag, value in (("--env", args.env), ("--hyperparams", args.hyperparams), ("--planner", args.planner)):
            validation.requirement(flag, value, value is None, "be left out with --config (config.yml holds it)")
        config = RunConfig.read(args.config, where="--config")
        settings, planner, seeds = distill_settings_of(config)
        settings = DistillSettings(**{**asdict(settings), **{k: v for k, v in given.items() if v is not None}})
        seeds = args.seeds or seeds
        if args.seed is not None:
            config = config.replace(seed=args.seed)
    else:
        validation.requirement("--env", args.env, args.env is not None, "be given (the task), or give --config")
        config = distill_config(args.env, seed=args.seed or 0, overrides=args.hyperparams, planner=planner)
        settings = DistillSettings(**{k: v for k, v in given.items() if v is not None})
        seeds = args.seeds or (0, 1000)
    res = distill(
        config,
        args.out,
        seeds=seeds,
        settings=settings,
        planner=planner,
        progress=not args.no_progress,
        force=args.force,
        command=_command(),
    )
    last = res["rounds"][-1]
    print(
        f"distilled {config.env_id}'s planner in {len(res['rounds'])} rounds ({res['pairs']} steps; the last round's "
        f"policy succeeded in {last['executed_success']:.0%} of its {last['episodes']} episodes; squared error "
        f"{last['mse']:.4f}) in {res['wall_time_s'] / 60:.1f} min; wrote {args.out} "
        f"(flatbody evaluate {args.out} --env {config.env_id})"
    )
    return 0


def _baseline_names() -> tuple[str, ...]:
    """Every baseline's name (read when ``--baselines`` is parsed: agents load only then)."""
    from agents.evaluate import ALL_BASELINES

    return ALL_BASELINES


@_trusting
def _evaluate(args) -> int:
    from agents.evaluate import evaluate_all, format_table

    if args.env is not None or args.out_dir or args.docs:
        return _evaluate_tasks(args)
    for flag, value in (
        ("--baselines", args.baselines),
        ("--planner", args.planner),
        ("--env-kwargs", args.env_kwargs),
    ):
        validation.requirement(flag, value, value is None, "go with --env (the reference report of a task)")
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
        from flatbody_env.output import shown_path

        update_docs(args.docs, REFERENCE_DIR)
        print(f"updated the table in {args.docs} from {shown_path(REFERENCE_DIR)}")
        return 0
    if args.model is not None and args.env == "all":
        raise ValueError("--env: give one task id with MODEL (all evaluates the shipped agents)")
    trained_on = _trained_on(args.model) if args.model is not None else None
    if trained_on is not None and args.env not in (None, trained_on):
        task_spec(args.env)  # an unknown id: that is the error
        validation.requirement(
            "--env", args.env, False, f"be {trained_on}, the task {args.model[:80]} was trained on (its config.yml)"
        )
    from agents.config import DEFAULT_ENV_ID

    ids = V1_IDS if args.env == "all" else (task_spec(args.env or trained_on or DEFAULT_ENV_ID).env_id,)
    from agents.planner import parse_overrides

    planner = parse_overrides(args.planner, "--planner") if args.planner else None  # checked before anything runs
    env_kwargs = None
    if args.env_kwargs:
        from agents.config import checked_env_kwargs, parse_env_kwargs

        for flag, given in (("--out-dir", args.out_dir), ("--docs", args.docs)):
            validation.requirement(
                "--env-kwargs",
                " ".join(args.env_kwargs),
                not given,
                f"not go with {flag} (a variant's report is not the reference table's: write it with --out FILE)",
            )
        env_kwargs = parse_env_kwargs(args.env_kwargs)
        for env_id in ids:
            checked_env_kwargs(env_id, env_kwargs, "--env-kwargs")
    if args.baselines is not None:
        from agents.evaluate import baselines_for

        for env_id in ids:
            for name in args.baselines:
                validation.string("--baselines", name, choices=baselines_for(env_id))
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
            only=None if args.baselines is None else tuple(args.baselines),
            planner=planner,
            env_kwargs=env_kwargs,
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


def _trained_on(model: str) -> str | None:
    """The task a run folder (or its model.zip) was trained on, as its config.yml says (read without unpickling
    anything); None when it does not say."""
    from pathlib import Path

    from agents.numpy_policy import read_run_config

    p = Path(model)
    folder = p if p.is_dir() else p.parent
    env_id = read_run_config(folder).get("env_id")
    if env_id is None and (folder / "model.zip").exists():
        return "FlatBody-v0"  # the runs of before config.yml named the task trained the default task of the time
    return env_id


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


_TRUST_HELP = (
    "allow unpickling a model from outside the shipped agent and your own runs (pickles can run code; "
    "docs/reliability.md)"
)


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


def _add_run_arguments(p, *, seed_default) -> None:
    """The flags every training command shares (train, curriculum): seed, budget, overrides, folder, checkpoints."""
    p.add_argument(
        "--seed",
        type=int_at_least("seed", 0, validation.MAX_SEED),
        default=seed_default,
        help="training seed (default 0)",
    )
    p.add_argument(
        "--n-timesteps",
        type=int_at_least("n_timesteps", 1, validation.MAX_TIMESTEPS),
        default=None,
        metavar="N",
        help="total environment steps (default: the YAML's; with --resume: a new, larger budget)",
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
        "--hyperparams",
        nargs="*",
        metavar="KEY=VALUE",
        help="override YAML entries (values parsed as YAML; dotted keys reach into mappings; checked as the file's)",
    )
    p.add_argument(
        "--trained-agent",
        metavar="RUN",
        help="fine-tune: start from this run folder's model.zip and vecnormalize.pkl (its network, statistics and "
        "residual form; this run's rollout and update settings; SB3 algorithms)",
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
        help="steps between checkpoints, the newest 3 kept (0: none; default 50000)",
    )
    p.add_argument("--keep-checkpoints", action="store_true", help="keep DIR/checkpoints after a completed run")
    p.add_argument(
        "--eval-freq",
        type=int_at_least("eval_freq", 0, validation.MAX_TIMESTEPS),
        default=0,
        metavar="N",
        help="every N env steps, the deterministic policy on held-out episodes: a row of DIR/evaluations.csv and a "
        "line on stderr, the time left out of the run's wall time (0: never; default 0)",
    )
    p.add_argument(
        "--eval-episodes",
        type=int_at_least("eval_episodes", 1, validation.MAX_EPISODES),
        default=None,
        metavar="K",
        help="with --eval-freq: held-out episodes per evaluation (default 100)",
    )
    p.add_argument(
        "--eval-seed",
        type=int_at_least("eval_seed", 0, validation.MAX_SEED),
        default=None,
        metavar="S",
        help="with --eval-freq: held-out episode i is reset with seed S + i (default 10000, the table's)",
    )
    p.add_argument(
        "--threads",
        type=int_at_least("threads", 1, validation.MAX_WORKERS),
        default=1,
        help="torch threads (default 1)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--trust", action="store_true", help=_TRUST_HELP)


def register(sub) -> None:
    from agents.config import ALGOS, DEFAULT_ENV_ID, SB3_ALGOS  # a light module: no torch, no SB3

    p = sub.add_parser(
        "train",
        help="train an agent: SB3's PPO, SAC or TD3, or rsl_rl's PPO (rsl-ppo), on any task (default FlatBody-v1)",
    )
    p.add_argument(
        "--algo",
        choices=ALGOS,
        help="algorithm (required for a new run; --resume and --config read it); rsl-ppo: rsl_rl's PPO on the torch "
        "vector env",
    )
    p.add_argument(
        "--env",
        default=None,
        metavar="ID",
        help=f"task id (docs/tasks.md; default {DEFAULT_ENV_ID}; --resume and --config read it from config.yml)",
    )
    _add_run_arguments(p, seed_default=None)
    p.add_argument("--hyperparams-file", metavar="FILE", help="YAML file (default: agents/hyperparams/ALGO.yml)")
    p.add_argument("--out", metavar="DIR", help="the run folder (default runs/ALGO-ENV-seedS)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in DIR from its newest checkpoint (task, algorithm and hyperparameters from its config.yml)",
    )
    p.add_argument(
        "--config",
        metavar="FILE",
        help="train a run's configuration again (a run folder's config.yml): the same algorithm, task, seed, "
        "hyperparameters and budget",
    )
    p.add_argument(
        "--device", choices=("cpu", "cuda"), default="cpu", help="torch device of env and policy (rsl-ppo; default cpu)"
    )
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
    p.set_defaults(handler=_train)

    p = sub.add_parser(
        "curriculum",
        help="train through a curriculum over one task keyword (the prior track: stages of the keyword's value)",
    )
    p.add_argument("--algo", choices=SB3_ALGOS, default="ppo", help="SB3 algorithm (default ppo)")
    p.add_argument("--env", required=True, metavar="ID", help="task id (docs/tasks.md)")
    p.add_argument("--out", metavar="DIR", help="the run folder (default runs/ALGO-ENV-curriculum-seedS)")
    _add_run_arguments(p, seed_default=0)
    p.add_argument("--device", choices=("cpu",), default="cpu", help=argparse.SUPPRESS)
    p.add_argument(
        "--key", default="min_settling_rate", help="the task keyword the stages set (default min_settling_rate)"
    )
    p.add_argument(
        "--stages",
        required=True,
        type=number_list("stages", low=-1e6, high=1e6),
        metavar="V0,V1,...",
        help="comma-separated values of the keyword, the last the task's own",
    )
    p.add_argument(
        "--advance-at",
        type=number("advance_at", low=0.0, high=1.0),
        default=0.8,
        help="training success rate that ends a stage (default 0.8)",
    )
    p.add_argument(
        "--min-stage-steps", type=int_at_least("min_stage_steps", 0, validation.MAX_TIMESTEPS), default=100_000
    )
    p.add_argument(
        "--max-stage-steps", type=int_at_least("max_stage_steps", 1, validation.MAX_TIMESTEPS), default=500_000
    )
    p.add_argument(
        "--window",
        type=int_at_least("window", 1, 10_000),
        default=2,
        help="rollouts whose finished episodes decide the success rate",
    )
    p.add_argument(
        "--train-env-kwargs",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="task keywords of the training environments only (reward shaping, e.g. w_tumble=0); "
        "the model is evaluated on the task's own",
    )
    p.add_argument(
        "--log-std-per-action",
        type=number_list("log_std_per_action", low=-20.0, high=2.0, max_items=16),
        default=None,
        metavar="L0,L1,...",
        help="initial log std of each action component (overrides policy_kwargs.log_std_init per component)",
    )
    p.set_defaults(handler=_curriculum)

    p = sub.add_parser("imitate", help="plan, then imitate: cross-entropy plans cloned into a residual agent's policy")
    steps = p.add_subparsers(dest="step", metavar="STEP", required=True, parser_class=type(p))
    q = steps.add_parser("plan", help="cross-entropy plans for seeded episodes of an additive residual agent's task")
    q.add_argument("--model", required=True, help="run folder of an additive residual agent (its task and residual)")
    q.add_argument("--seeds", required=True, type=seed_range("seeds"), help="LO:HI, training seeds (HI excluded)")
    q.add_argument("--out", required=True, type=output_file("out", (".npz",)), help="plans file (.npz)")
    for name, low, high, default in (
        ("knots", 1, 400, 16),
        ("samples", 2, 4096, 64),
        ("iterations", 1, 10_000, 40),
        ("elite", 1, 4096, 8),
        ("chunk", 1, 4096, 32),
    ):
        q.add_argument(f"--{name}", type=int_at_least(name, low, high), default=default, help=f"(default {default})")
    q.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=0, help="seed of the draws")
    q.add_argument("--init-std", type=number("init_std", low=0.0, high=10.0), default=0.5)
    q.add_argument("--reach", type=number("reach", low=0.0, high=10.0), default=0.02)
    q.add_argument("--on-policy", action="store_true", help="plan corrections of the run's own policy (a second round)")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.add_argument("--trust", action="store_true", help=_TRUST_HELP)
    q = steps.add_parser("clone", help="fit a PPO run's policy to the successful plans: a new run folder")
    q.add_argument("--plans", required=True, nargs="+", help="plans files (joined)")
    q.add_argument("--model", required=True, help="the PPO run folder to start from")
    q.add_argument("--out", required=True, help="the new run folder")
    q.add_argument("--epochs", type=int_at_least("epochs", 1, 10_000), default=20)
    q.add_argument("--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=0, help="seed of the fit")
    q.add_argument("--force", action="store_true", help="write into DIR even if it holds a run (overwrites it)")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.add_argument("--trust", action="store_true", help=_TRUST_HELP)
    q = steps.add_parser("distill", help="DAgger of the task's planner into a PPO policy: a new run folder")
    q.add_argument("--env", metavar="ID", help="the task (its planner is the expert); or --config")
    q.add_argument("--config", metavar="FILE", help="a distilled run's config.yml: distil it again as it was made")
    q.add_argument("--out", required=True, metavar="DIR", help="the new run folder")
    q.add_argument(
        "--seeds", type=seed_range("seeds"), default=None, help="LO:HI, training episodes (HI excluded; default 0:1000)"
    )
    q.add_argument(
        "--seed", type=int_at_least("seed", 0, validation.MAX_SEED), default=None, help="weights, fit, noise"
    )
    for name, low, high, default, what in (
        ("rounds", 1, 100, 5, "DAgger rounds: the first runs the planner, each later one the policy so far"),
        ("epochs", 1, 10_000, 30, "epochs of the fit after each round"),
        ("batch-size", 1, 1 << 20, 512, "minibatch of the fit"),
    ):
        key = name.replace("-", "_")
        q.add_argument(f"--{name}", type=int_at_least(key, low, high), default=None, help=f"{what} (default {default})")
    q.add_argument(
        "--learning-rate",
        type=number("learning_rate", low=1e-8, high=1.0),
        default=None,
        help="Adam's rate, annealed to 0 over each fit (default 0.001)",
    )
    q.add_argument("--hyperparams", nargs="*", metavar="KEY=VALUE", help="override the PPO entry (network, residual)")
    q.add_argument("--planner", nargs="+", metavar="KEY=VALUE", help="the expert's settings (as evaluate's)")
    q.add_argument("--force", action="store_true", help="write into DIR even if it holds a run (overwrites it)")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(handler=_imitate)

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
    p.add_argument(
        "--baselines",
        type=name_list("baselines", _baseline_names),
        default=None,
        metavar="A,B",
        help="with --env: evaluate only these baselines (zero, random, heuristic = the LQR, passivity; pumping on the "
        "reach tasks; planner; witness where the starts are witnessed)",
    )
    p.add_argument(
        "--planner",
        nargs="+",
        default=None,
        metavar="KEY=VALUE",
        help="with --env: the planner's settings (samples, horizon, knots, noise, iterations, prior, ...; "
        "docs/tasks.md), e.g. samples=256 horizon=160 knots=24",
    )
    p.add_argument(
        "--env-kwargs",
        nargs="+",
        default=None,
        metavar="KEY=VALUE",
        help="with --env: a variant of the task, its registered keywords changed (docs/env.md; VALUE read as YAML), "
        "e.g. observe_body=true; every policy, the targets and the planner's model run on it; the report records "
        "them (not with --out-dir or --docs: the reference table holds the registered tasks)",
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument(
        "--out",
        type=output_file("out"),
        metavar="FILE",
        help="also write the JSON report here (checked before evaluating)",
    )
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
        type=output_dir("out_dir"),
        default=None,
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
