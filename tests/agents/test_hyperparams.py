"""Every hyperparameter of every trainer through the one validator set (agents.config, flatbody_env.physics.validation):
hostile values are one line naming the field (exit 2), the same from a YAML file as from a flag, before anything is
written or allocated; every algorithm has a from-scratch entry for every v1 task."""

from __future__ import annotations

import pytest

from agents.config import ALGOS, FIELDS, RunConfig, check_hyperparams, load_hyperparams, resolve
from flatbody_env.cli.main import main
from flatbody_env.env.registration import V1_IDS
from flatbody_env.physics import validation


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("env_id", V1_IDS)
def test_every_algorithm_has_a_checked_from_scratch_entry_for_every_v1_task(algo, env_id):
    hp = load_hyperparams(algo, env_id)
    assert hp.get("residual") is None, "the v1 entries train from scratch: no controller prior"
    checked = check_hyperparams(algo, hp, env_id)
    assert checked["n_timesteps"] >= 1 and checked["n_envs"] >= 1
    assert resolve(algo, env_id).prior is None


def test_the_v0_entries_are_the_labelled_prior_track():
    for env_id in ("FlatBody-v0", "FlatBodySlow-v0", "FlatBodyTorque-v0"):
        assert resolve("ppo", env_id).prior == {"residual": "heuristic"}
    assert resolve("rsl-ppo", "FlatBody-v0").prior == {"residual": "heuristic"}


BUDGET = {"ppo": "4096", "sac": "2000", "td3": "2000", "rsl-ppo": "16384"}
"""A short run of the default entry of each algorithm (one collection), were a hostile value accepted."""
# (algo, override, the field the refusal names)
HOSTILE = [
    ("ppo", "n_steps=0", "hyperparams.n_steps"),
    ("ppo", "n_steps=abc", "hyperparams.n_steps"),
    ("ppo", "batch_size=300", "hyperparams.batch_size"),  # does not divide n_steps x n_envs
    ("ppo", "batch_size=1", "hyperparams.batch_size"),
    ("ppo", "n_epochs=0", "hyperparams.n_epochs"),
    ("ppo", "gamma=1.5", "hyperparams.gamma"),
    ("ppo", "clip_range=-1", "hyperparams.clip_range"),
    ("ppo", "learning_rate=0", "hyperparams.learning_rate"),
    ("ppo", "learning_rate=nan", "hyperparams.learning_rate"),
    ("ppo", "use_sde=maybe", "hyperparams.use_sde"),
    ("ppo", "target_kl=-1", "hyperparams.target_kl"),
    ("ppo", "n_timesteps=.inf", "hyperparams.n_timesteps"),
    ("ppo", "n_timesteps=1e300", "hyperparams.n_timesteps"),
    ("ppo", "n_envs=0", "hyperparams.n_envs"),
    ("ppo", "policy_kwargs.net_arch=[]", "hyperparams.policy_kwargs.net_arch"),
    ("ppo", "policy_kwargs.net_arch=[64,-1]", "hyperparams.policy_kwargs.net_arch[1]"),
    ("ppo", "policy_kwargs.activation_fn=sigmoid", "hyperparams.policy_kwargs.activation_fn"),
    ("ppo", "policy_kwargs.log_std_init=1e300", "hyperparams.policy_kwargs.log_std_init"),
    ("ppo", "policy_kwargs.nope=1", "hyperparams.policy_kwargs.nope"),
    ("ppo", "policy=CnnPolicy", "hyperparams.policy"),
    ("ppo", "normalize=sometimes", "hyperparams.normalize"),
    ("ppo", "residual=lqr", "hyperparams.residual"),
    ("ppo", "residual_scale=2", "hyperparams.residual_scale"),  # without a residual
    ("ppo", "seed=3", "hyperparams.seed"),
    ("ppo", "device=cuda", "hyperparams.device"),
    ("ppo", "no_such_key=1", "hyperparams.no_such_key"),
    ("ppo", "env_kwargs.torque_limit=-1", "hyperparams.env_kwargs.torque_limit"),
    ("ppo", "n_steps=100000", "hyperparams.n_steps"),  # a rollout buffer of GiB: refused before it is allocated
    ("ppo", "policy_kwargs.net_arch=[4096,4096,4096,4096,4096,4096,4096,4096]", "hyperparams.policy_kwargs.net_arch"),
    ("ppo", "critic_warmup=-1", "hyperparams.critic_warmup"),
    ("ppo", "fine_tune_log_std=nan", "hyperparams.fine_tune_log_std"),
    ("ppo", "fine_tune_log_std=-3", "hyperparams.fine_tune_log_std"),  # without a trained agent
    ("sac", "critic_warmup=1000", "hyperparams.critic_warmup"),  # PPO's
    ("sac", "buffer_size=0", "hyperparams.buffer_size"),
    ("sac", "buffer_size=1e9", "hyperparams.buffer_size"),  # 100+ GiB of replay buffer
    ("sac", "batch_size=1000000", "hyperparams.batch_size"),  # more than the buffer holds
    ("sac", "learning_starts=1e9", "hyperparams.learning_starts"),  # never trains within n_timesteps
    ("sac", "gradient_steps=0", "hyperparams.gradient_steps"),
    ("sac", "tau=0", "hyperparams.tau"),
    ("sac", "ent_coef=sometimes", "hyperparams.ent_coef"),
    ("sac", "train_freq=[1,second]", "hyperparams.train_freq"),
    ("sac", "use_sde=maybe", "hyperparams.use_sde"),
    ("sac", "policy_kwargs.n_critics=0", "hyperparams.policy_kwargs.n_critics"),
    ("td3", "policy_delay=0", "hyperparams.policy_delay"),
    ("td3", "target_policy_noise=-1", "hyperparams.target_policy_noise"),
    ("td3", "noise_type=pink", "hyperparams.noise_type"),
    ("td3", "noise_std=1e9", "hyperparams.noise_std"),
    ("td3", "ent_coef=auto", "hyperparams.ent_coef"),  # SAC's, not TD3's
    ("rsl-ppo", "num_mini_batches=0", "hyperparams.num_mini_batches"),
    ("rsl-ppo", "num_mini_batches=100000", "hyperparams.num_mini_batches"),
    ("rsl-ppo", "num_steps_per_env=0", "hyperparams.num_steps_per_env"),
    ("rsl-ppo", "hidden_dims=[]", "hyperparams.hidden_dims"),
    ("rsl-ppo", "clip_param=-1", "hyperparams.clip_param"),
    ("rsl-ppo", "init_std=1e300", "hyperparams.init_std"),
    ("rsl-ppo", "desired_kl=-1", "hyperparams.desired_kl"),
    ("rsl-ppo", "schedule=sometimes", "hyperparams.schedule"),
    ("rsl-ppo", "learn_std=maybe", "hyperparams.learn_std"),
    ("rsl-ppo", "activation=sigmoid", "hyperparams.activation"),
    ("rsl-ppo", "gamma=0", "hyperparams.gamma"),
    ("rsl-ppo", "residual=passivity", "hyperparams.residual"),
    ("rsl-ppo", "n_envs=65536", "hyperparams.num_steps_per_env"),  # the rollout storage: GiB
    ("rsl-ppo", "seed=3", "hyperparams.seed"),
    ("rsl-ppo", "nope=1", "hyperparams.nope"),
]


@pytest.mark.parametrize("algo, override, field", HOSTILE, ids=[f"{a}-{o[:40]}" for a, o, _ in HOSTILE])
def test_hostile_hyperparameters_are_one_line_naming_the_field(tmp_path, capsys, algo, override, field):
    out = tmp_path / "run"
    budget = [] if override.startswith("n_timesteps") else ["--n-timesteps", BUDGET[algo]]  # short, were it accepted
    argv = ["train", "--algo", algo, "--out", str(out), "--no-progress", *budget, "--hyperparams", override]
    assert main(argv) == 2
    line = _one_line(capsys)
    assert line.startswith(f"flatbody train: error: {field}: "), line
    assert not out.exists()  # nothing written, the folder not trusted


@pytest.mark.parametrize(
    "algo, override, field",
    [
        h
        for h in HOSTILE
        if h[1].split("=")[0] in ("n_steps", "n_timesteps", "buffer_size", "num_mini_batches", "init_std")
    ],
)
def test_a_yaml_file_gets_the_same_checks_as_the_flags(tmp_path, capsys, algo, override, field):
    """``--hyperparams-file`` with the same hostile value in the entry: the same refusal, naming the same field."""
    key, value = override.split("=", 1)
    entry = load_hyperparams(algo, "FlatBody-v1")
    lines = ["FlatBody-v1:"] + [f"  {k}: {v!r}" if isinstance(v, str) else f"  {k}: {v}" for k, v in entry.items()]
    lines = [ln for ln in lines if not ln.startswith(f"  {key}:")] + [f"  {key}: {value}"]
    file = tmp_path / "hp.yml"
    file.write_text("\n".join(lines).replace("None", "null").replace("True", "true").replace("False", "false") + "\n")
    out = tmp_path / "run"
    budget = [] if key == "n_timesteps" else ["--n-timesteps", BUDGET[algo]]
    assert (
        main(["train", "--algo", algo, "--hyperparams-file", str(file), "--out", str(out), "--no-progress", *budget])
        == 2
    )
    assert _one_line(capsys).startswith(f"flatbody train: error: {field}: ")
    assert not out.exists()


def test_a_run_config_gets_the_same_checks(tmp_path, capsys):
    """A hostile value in a run's config.yml (``--config``) is refused naming the field of config.yml."""
    import yaml

    cfg = resolve("ppo", "FlatBody-v1").mapping()
    cfg["hyperparams"]["n_steps"] = 0
    (tmp_path / "config.yml").write_text(yaml.safe_dump(cfg))
    assert main(["train", "--config", str(tmp_path / "config.yml"), "--out", str(tmp_path / "o")]) == 2
    assert _one_line(capsys).startswith("flatbody train: error: config.yml.hyperparams.n_steps: ")
    cfg["hyperparams"]["n_steps"] = 256
    cfg["algo"] = "a2c"
    (tmp_path / "config.yml").write_text(yaml.safe_dump(cfg))
    assert main(["train", "--config", str(tmp_path / "config.yml"), "--out", str(tmp_path / "o")]) == 2
    assert _one_line(capsys).startswith("flatbody train: error: config.yml.algo: ")
    assert not (tmp_path / "o").exists()


def test_memory_is_predicted_from_the_settings_and_bounded():
    from agents.config import predicted_bytes

    hp = check_hyperparams("sac", load_hyperparams("sac", "FlatBody-v1"), "FlatBody-v1")
    buffer, nets = predicted_bytes("sac", hp, 16, 4)
    assert buffer == 4 * hp["buffer_size"] * (2 * 16 + 4 + 3)  # observations twice, actions, reward, done, timeout
    assert 0 < nets < buffer
    bigger = {**hp, "buffer_size": 2 * hp["buffer_size"]}
    assert predicted_bytes("sac", bigger, 16, 4)[0] == 2 * buffer
    n = validation.MAX_TRAINER_BYTES // (4 * (2 * 16 + 4 + 3))  # the largest buffer within the bound, about
    with pytest.raises(ValueError, match=r"^hyperparams\.buffer_size: must keep"):
        check_hyperparams("sac", {**hp, "buffer_size": n + 1000}, "FlatBody-v1")
    check_hyperparams("sac", {**hp, "buffer_size": n // 2}, "FlatBody-v1")


def test_every_field_table_refuses_unknown_keys_and_names_flags():
    for algo, table in FIELDS.items():
        assert table["seed"].flag == "--seed" and table["device"].flag == "--device", algo
        with pytest.raises(ValueError, match=r"^hyperparams\.zzz: unknown field \(allowed: "):
            validation.fields("hyperparams", {"zzz": 1}, table)


def test_the_field_kinds_read_yaml_1_1_numbers_and_nothing_else():
    F = validation.Field
    assert validation.field("x", "3e-4", F(kind="number", positive=True)) == 3e-4  # YAML 1.1 reads 3e-4 as a string
    assert validation.field("x", "1e5", F(kind="integer", low=1)) == 100_000
    assert validation.field("x", 2.0, F(kind="integer")) == 2
    for value, spec in (
        (2.5, F(kind="integer")),
        (True, F(kind="integer")),
        (True, F(kind="number")),
        ("yes", F(kind="boolean")),
        (1, F(kind="boolean")),
        ([1, 2], F(kind="choice", choices=(1, 2))),
        ({"pi": []}, F(kind="layers", low=1, high=8, choices=("pi",))),
        ({"xx": [8]}, F(kind="layers", low=1, high=8, choices=("pi",))),
        (None, F(kind="number")),
        (list(range(100)), F(kind="integers", low=0, high=1000)),
    ):
        with pytest.raises(ValueError, match=r"^x"):
            validation.field("x", value, spec)


def test_device_cuda_without_a_gpu_is_one_line_naming_the_flag(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("a GPU is here")
    for algo in ("rsl-ppo", "ppo"):
        assert main(["train", "--algo", algo, "--device", "cuda", "--out", str(tmp_path / "o"), "--no-progress"]) == 2
        line = _one_line(capsys)
        assert line.startswith("flatbody train: error: --device: ") and "internal error" not in line, line
    assert not (tmp_path / "o").exists()


def test_the_shipped_agents_configurations_read_and_check(tmp_path):
    """Every agents/models/* config.yml reads as a RunConfig whose prior is labelled: the v0 agents' (format 1) on the
    prior track, the shipped v1 agent's (format 2) from scratch, the distilled v1 agents' (format 2) on the prior track:
    a residual on the law their planner perturbs and the distillation that fitted it (``distilled-clock-ID``: with the
    episode's elapsed time in the observation, its env_kwargs say)."""
    from agents.numpy_policy import MODELS_DIR, SHIPPED_AGENT

    for folder in sorted(MODELS_DIR.iterdir()):
        config = RunConfig.read(folder)
        distilled = folder.name.startswith("distilled-")
        assert config.env_id.endswith("-v1" if folder.name == SHIPPED_AGENT or distilled else "-v0")
        assert config.seed >= 0
        if distilled:
            assert set(config.prior) == {"residual", "imitation"} and config.imitation["method"] == "distill"
            # distilled-clock-ID: the same with the episode's elapsed time observed (a variant, named so)
            clock = bool(config.env_kwargs.get("observe_time"))
            assert folder.name == f"distilled-{'clock-' if clock else ''}{config.env_id}" and config.algo == "ppo"
        else:
            assert config.prior is None or set(config.prior) <= {"residual", "trained_agent", "curriculum"}
    shipped = RunConfig.read(MODELS_DIR / SHIPPED_AGENT)
    assert shipped.prior is None and shipped.env_id == "FlatBody-v1" and shipped.hyperparams["residual"] is None
    assert RunConfig.read(MODELS_DIR / "rsl-ppo-FlatBody-v0").algo == "rsl-ppo"
    assert RunConfig.read(MODELS_DIR / "ppo-FlatBodyTorque-v0").curriculum["key"] == "min_uncontrolled_offset"
