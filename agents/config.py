"""What a training run is: its algorithm, task, seed, budget and hyperparameters, each checked, and its ``config.yml``.

Every trainer (``flatbody train --algo ppo|sac|td3|rsl-ppo``, ``flatbody curriculum``, ``flatbody imitate clone``)
starts from a :class:`RunConfig` and writes it as the run folder's ``config.yml`` (:mod:`agents.runs`); ``flatbody
train --config FOLDER/config.yml`` trains that configuration again, and ``--resume`` continues it.

Hyperparameters come from ``agents/hyperparams/<algo>.yml`` (RL-Zoo layout: one entry per environment id;
:func:`load_hyperparams`), updated by ``--hyperparams KEY=VALUE`` overrides (:func:`apply_overrides`; dotted keys
reach into mappings). Each algorithm's hyperparameters are described once, as
:class:`~flatbody_env.physics.validation.Field` tables (:data:`FIELDS`), and checked by the one validator set
(:func:`check_hyperparams`): types, ranges, the combinations (``n_steps × n_envs`` divisible by ``batch_size``,
``batch_size`` ≤ ``buffer_size``, ``num_mini_batches`` ≤ the transitions of a rollout, …) and the memory the run's
buffers and networks are predicted to take (at most
:data:`~flatbody_env.physics.validation.MAX_TRAINER_BYTES`), before anything heavy is imported or allocated. A file
entry gets exactly the checks a flag gets; an error names the field (``hyperparams.n_steps: must be …``).

Two tracks share the files: the entries of the v1 ids (:data:`flatbody_env.env.registration.V1_IDS`) train from
scratch (no controller prior: no ``residual``); the v0 entries are the *prior* track (a residual on the LQR or the
passivity law, curricula, fine-tuning from a cloned policy), kept so that the shipped agents of ``agents/models/``
reproduce. A run's ``config.yml`` says which (``prior``: null from scratch).

This module is light (no torch, no Stable-Baselines3): a refusal comes before the heavy imports.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from flatbody_env.output import shown_path
from flatbody_env.physics import validation
from flatbody_env.physics.validation import Field

ALGOS = ("ppo", "sac", "td3", "rsl-ppo")
"""The algorithms of ``flatbody train --algo``: Stable-Baselines3's PPO, SAC and TD3, and rsl_rl's PPO."""
SB3_ALGOS = ("ppo", "sac", "td3")
"""The algorithms Stable-Baselines3 trains (:mod:`agents.train`); ``rsl-ppo`` is rsl_rl's (:mod:`agents.rsl`)."""
MODEL_FORMATS = SB3_ALGOS
"""The SB3 class a ``model.zip`` is saved as (rsl-ppo's actor is exported as an SB3 ``PPO`` model)."""
DEFAULT_ENV_ID = "FlatBody-v1"
"""The task of ``flatbody train`` without ``--env`` (the easy rung of the v1 suite)."""
DEVICES = ("cpu", "cuda")
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
CONFIG_FORMAT = 2
"""The layout of ``config.yml`` written now (:meth:`RunConfig.mapping`); format 1 (the shipped v0 agents' files, with
no ``format`` key) is read too."""
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
"""Activations of the SB3 policies' ``policy_kwargs.activation_fn``."""
RSL_ACTIVATIONS = ("tanh", "relu", "elu")
"""Activations of rsl-ppo's ``activation`` (those its SB3 export and the numpy policy run)."""

_I, _N, _B, _C = "integer", "number", "boolean", "choice"
MAX_LAYERS = 8
"""Most hidden layers of a network (``net_arch``, ``hidden_dims``)."""
MAX_WIDTH = 4096
"""Widest hidden layer."""
_LAYERS = {"kind": "layers", "low": 1, "high": MAX_WIDTH, "max_items": MAX_LAYERS}
_FLAGS = {"seed": Field(kind=_I, flag="--seed"), "device": Field(kind=_C, flag="--device")}
_RUN = {
    "n_timesteps": Field(kind=_I, low=1, high=validation.MAX_TIMESTEPS),
    "n_envs": Field(kind=_I, low=1, high=validation.MAX_BATCH),
    "env_kwargs": Field(kind="mapping"),  # checked by the env itself (flatbody_env.env.core.configure)
}
_SB3 = {
    **_RUN,
    "policy": Field(kind=_C, choices=("MlpPolicy",)),
    "normalize": Field(
        kind="switch",
        fields={
            "norm_obs": Field(kind=_B),
            "norm_reward": Field(kind=_B),
            "clip_obs": Field(kind=_N, positive=True, high=1e6),
            "clip_reward": Field(kind=_N, positive=True, high=1e6),
        },
    ),
    # the prior track (agents.heuristic.ResidualAction) and training-only reward terms
    "residual": Field(kind=_C, choices=(None, "heuristic", "passivity", "pumping"), nullable=True),
    "residual_mode": Field(kind=_C, choices=("gain", "additive")),
    "residual_scale": Field(kind=_N, low=0.0, high=100.0),
    "residual_gate": Field(kind=_N, low=0.0, high=10.0),
    "success_bonus": Field(kind=_N, low=0.0, high=1000.0),
    "precision_bonus": Field(kind=_N, low=0.0, high=1000.0),
    "learning_rate": Field(kind=_N, positive=True, high=1.0),
    "gamma": Field(kind=_N, low=0.0, high=1.0),
    "stats_window_size": Field(kind=_I, low=1, high=1_000_000),
    **_FLAGS,
}
_OFF_POLICY = {
    **_SB3,
    "buffer_size": Field(kind=_I, low=1, high=validation.MAX_TIMESTEPS),
    "learning_starts": Field(kind=_I, low=0, high=validation.MAX_TIMESTEPS),
    "batch_size": Field(kind=_I, low=1, high=1 << 20),
    "tau": Field(kind=_N, positive=True, high=1.0),
    "train_freq": Field(kind="frequency", low=1, high=1_000_000, choices=("step", "episode")),
    "gradient_steps": Field(kind=_I, low=-1, high=10_000),
    "noise_type": Field(kind=_C, choices=(None, "normal", "ornstein-uhlenbeck"), nullable=True),
    "noise_std": Field(kind=_N, low=0.0, high=10.0),
}
FIELDS: dict[str, dict[str, Field]] = {
    "ppo": {
        **_SB3,
        "n_steps": Field(kind=_I, low=1, high=validation.MAX_EPISODE_STEPS),
        "batch_size": Field(kind=_I, low=2, high=1 << 20),
        "n_epochs": Field(kind=_I, low=1, high=1000),
        "gae_lambda": Field(kind=_N, low=0.0, high=1.0),
        "clip_range": Field(kind=_N, positive=True, high=10.0),
        "clip_range_vf": Field(kind=_N, positive=True, high=1e6, nullable=True),
        "normalize_advantage": Field(kind=_B),
        "ent_coef": Field(kind=_N, low=0.0, high=10.0),
        "vf_coef": Field(kind=_N, low=0.0, high=1000.0),
        "max_grad_norm": Field(kind=_N, positive=True, high=1e6),
        "use_sde": Field(kind=_B),
        "sde_sample_freq": Field(kind=_I, low=-1, high=1_000_000),
        "target_kl": Field(kind=_N, positive=True, high=10.0, nullable=True),
        # fine-tuning a trained agent (agents.train): its exploration, and a first stretch that fits the critic alone
        "fine_tune_log_std": Field(kind=_N, low=-20.0, high=2.0),
        "critic_warmup": Field(kind=_I, low=0, high=validation.MAX_TIMESTEPS),
        "policy_kwargs": Field(
            kind="mapping",
            fields={
                "net_arch": Field(**_LAYERS, choices=("pi", "vf")),
                "activation_fn": Field(kind=_C, choices=ACTIVATIONS),
                "log_std_init": Field(kind=_N, low=-20.0, high=2.0),
                "ortho_init": Field(kind=_B),
                "full_std": Field(kind=_B),
                "use_expln": Field(kind=_B),
                "squash_output": Field(kind=_B),
                "share_features_extractor": Field(kind=_B),
            },
        ),
    },
    "sac": {
        **_OFF_POLICY,
        "ent_coef": Field(kind=_N, positive=True, high=100.0, choices=("auto",)),
        "target_update_interval": Field(kind=_I, low=1, high=1_000_000),
        "target_entropy": Field(kind=_N, low=-1000.0, high=1000.0, choices=("auto",)),
        "use_sde": Field(kind=_B),
        "sde_sample_freq": Field(kind=_I, low=-1, high=1_000_000),
        "use_sde_at_warmup": Field(kind=_B),
        "policy_kwargs": Field(
            kind="mapping",
            fields={
                "net_arch": Field(**_LAYERS, choices=("pi", "qf")),
                "activation_fn": Field(kind=_C, choices=ACTIVATIONS),
                "log_std_init": Field(kind=_N, low=-20.0, high=2.0),
                "use_expln": Field(kind=_B),
                "clip_mean": Field(kind=_N, positive=True, high=100.0),
                "n_critics": Field(kind=_I, low=1, high=10),
                "share_features_extractor": Field(kind=_B),
            },
        ),
    },
    "td3": {
        **_OFF_POLICY,
        "policy_delay": Field(kind=_I, low=1, high=1000),
        "target_policy_noise": Field(kind=_N, low=0.0, high=10.0),
        "target_noise_clip": Field(kind=_N, low=0.0, high=10.0),
        "policy_kwargs": Field(
            kind="mapping",
            fields={
                "net_arch": Field(**_LAYERS, choices=("pi", "qf")),
                "activation_fn": Field(kind=_C, choices=ACTIVATIONS),
                "n_critics": Field(kind=_I, low=1, high=10),
                "share_features_extractor": Field(kind=_B),
            },
        ),
    },
    "rsl-ppo": {
        **_RUN,
        # the prior track: the LQR's action, scheduled by the policy (agents.rsl.TorchResidual)
        "residual": Field(kind=_C, choices=(None, "heuristic"), nullable=True),
        "residual_mode": Field(kind=_C, choices=("gain", "additive")),
        "residual_scale": Field(kind=_N, low=0.0, high=100.0),
        # rsl_rl's runner and PPO (its names), but for noise_hold_steps, learn_std and normalize_reward
        "num_steps_per_env": Field(kind=_I, low=1, high=100_000),
        "stagger": Field(kind=_B),
        "hidden_dims": Field(kind="integers", low=1, high=MAX_WIDTH, max_items=MAX_LAYERS),
        "activation": Field(kind=_C, choices=RSL_ACTIVATIONS),
        "init_std": Field(kind=_N, positive=True, high=10.0),
        "learn_std": Field(kind=_B),
        "noise_hold_steps": Field(kind=_I, low=1, high=100_000),
        "obs_normalization": Field(kind=_B),
        "normalize_reward": Field(kind=_B),
        "num_learning_epochs": Field(kind=_I, low=1, high=1000),
        "num_mini_batches": Field(kind=_I, low=1, high=65_536),
        "clip_param": Field(kind=_N, positive=True, high=10.0),
        "use_clipped_value_loss": Field(kind=_B),
        "gamma": Field(kind=_N, positive=True, high=1.0),
        "lam": Field(kind=_N, low=0.0, high=1.0),
        "value_loss_coef": Field(kind=_N, low=0.0, high=1000.0),
        "entropy_coef": Field(kind=_N, low=0.0, high=10.0),
        "learning_rate": Field(kind=_N, positive=True, high=1.0),
        "max_grad_norm": Field(kind=_N, positive=True, high=1e6),
        "schedule": Field(kind=_C, choices=("adaptive", "fixed")),
        "desired_kl": Field(kind=_N, positive=True, high=10.0),
        **_FLAGS,
    },
}
"""Every hyperparameter of every algorithm, as the one validator set checks it (:func:`check_hyperparams`)."""

RSL_DEFAULTS: dict[str, Any] = {
    "n_timesteps": 1_000_000,
    "n_envs": 256,
    "env_kwargs": {},
    "residual": None,
    "residual_mode": "gain",
    "residual_scale": 1.0,
    "num_steps_per_env": 64,
    "stagger": True,
    "hidden_dims": [64, 64],
    "activation": "tanh",
    "init_std": 1.0,
    "learn_std": True,
    "noise_hold_steps": 1,
    "obs_normalization": True,
    "normalize_reward": False,
    "num_learning_epochs": 5,
    "num_mini_batches": 4,
    "clip_param": 0.2,
    "use_clipped_value_loss": True,
    "gamma": 0.99,
    "lam": 0.95,
    "value_loss_coef": 1.0,
    "entropy_coef": 0.0,
    "learning_rate": 1.0e-3,
    "max_grad_norm": 1.0,
    "schedule": "adaptive",
    "desired_kl": 0.01,
}
"""rsl-ppo's value of every key an entry of ``rsl-ppo.yml`` leaves out (rsl_rl's own PPO defaults, no prior); the
entries of the file (the v0 residual agent's, the v1 tasks') say what they use."""


def check_algo(algo: Any, where: str = "algo") -> str:
    """``algo`` if it is one of :data:`ALGOS`, else a ``ValueError`` naming ``where``."""
    return validation.field(where, algo, Field(kind=_C, choices=ALGOS))


def check_device(device: Any, where: str = "device") -> str:
    """``device`` if it is ``"cpu"``, or ``"cuda"`` with a CUDA GPU that torch can use; else a one-line ``ValueError``
    naming ``where`` (never an error deep inside a trainer)."""
    validation.field(where, device, Field(kind=_C, choices=DEVICES))
    if device == "cuda":
        import torch

        if not torch.cuda.is_available():
            validation.requirement(
                where, device, False, "be cpu here: no CUDA GPU is available (torch.cuda.is_available() is False)"
            )
    return device


def hyperparams_path(algo: str) -> Path:
    """The shipped hyperparameter file of ``algo`` (``agents/hyperparams/<algo>.yml``)."""
    return HYPERPARAMS_DIR / f"{check_algo(algo)}.yml"


def load_hyperparams(algo: str, env_id: str = DEFAULT_ENV_ID, path: str | Path | None = None) -> dict[str, Any]:
    """The YAML entry of ``env_id`` in ``hyperparams/<algo>.yml`` (or ``path``), deep-copied, as written (not yet
    checked: :func:`check_hyperparams`). rsl-ppo's entries are completed from :data:`RSL_DEFAULTS`."""
    check_algo(algo)
    file = Path(path) if path else hyperparams_path(algo)
    where = "hyperparams_file" if path else "hyperparams"
    data = validation.read_yaml(where, file) or {}  # the one reading door: bounded, no alias bombs
    if not isinstance(data, dict):
        raise ValueError(f"{where}: {str(file)!r} must hold a mapping of environment ids, got a {type(data).__name__}")
    if env_id not in data:
        raise ValueError(
            f"env: no {algo} hyperparameters for {env_id!r} in {file} (has: {', '.join(map(str, data)) or 'none'})"
        )
    entry = data[env_id]
    validation.requirement(where, entry, isinstance(entry, dict), f"map {env_id!r} in {file} to a mapping")
    entry = copy.deepcopy(entry)
    return {**copy.deepcopy(RSL_DEFAULTS), **entry} if algo == "rsl-ppo" else entry


def apply_overrides(hp: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """``key=value`` overrides (value parsed as YAML, without alias expansion; dotted keys reach into mappings)."""
    hp = copy.deepcopy(hp)
    for item in overrides:
        if not isinstance(item, str) or "=" not in item:
            raise ValueError(f"hyperparams: expected KEY=VALUE, got {str(item)[:60]!r}")
        key, text = item.split("=", 1)
        parts = key.strip().split(".")
        if not all(parts):
            raise ValueError(f"hyperparams: expected KEY=VALUE with a key, got {item[:60]!r}")
        value = validation.parse_yaml(f"hyperparams.{key.strip()[:60]}", text)
        node = hp
        for p in parts[:-1]:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise ValueError(f"hyperparams.{key.strip()[:60]}: reaches into a value that is not a mapping")
        node[parts[-1]] = value
    return hp


def parse_env_kwargs(items: list[str] | None, where: str = "--env-kwargs") -> dict[str, Any]:
    """``["observe_body=true", "dt=0.1"]`` → ``{"observe_body": True, "dt": 0.1}`` (each VALUE read as YAML, plain data
    only); ``ValueError`` naming ``where`` for an item that is not KEY=VALUE. The keywords themselves are checked by
    :func:`checked_env_kwargs`."""
    out: dict[str, Any] = {}
    for item in items or []:
        key, eq, text = str(item).partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise validation.refusal(where, "be KEY=VALUE with KEY a keyword of the env (docs/env.md)", item)
        out[key] = validation.parse_yaml(f"{where}.{key[:60]}", text)
    return out


def checked_env_kwargs(env_id: str, env_kwargs: dict[str, Any], where: str):
    """The configuration (:class:`~flatbody_env.env.core.EnvConfig`) of the task ``env_id`` with its registered keywords
    updated by ``env_kwargs`` (no env is built); a keyword the env refuses is a ``ValueError`` named
    ``<where>.<keyword>``, an unknown one a ``ValueError`` naming ``where``."""
    from flatbody_env.env.core import configure
    from flatbody_env.env.registration import task_spec

    kwargs = {**task_spec(env_id).kwargs, **env_kwargs}
    try:
        return configure(**kwargs)
    except ValueError as exc:
        raise ValueError(f"{where}.{exc}") from None
    except TypeError as exc:  # an unknown keyword
        raise ValueError(f"{where}: {' '.join(str(exc).split())[:160]}") from None


def _dims(env_id: str, env_kwargs: dict[str, Any], where: str) -> tuple[int, int]:
    """(observation size, action size) of the task with ``env_kwargs`` (:func:`checked_env_kwargs`, named
    ``<where>.env_kwargs``)."""
    cfg = checked_env_kwargs(env_id, env_kwargs, f"{where}.env_kwargs")
    return int(cfg.observation_space.shape[0]), int(cfg.action_space.shape[0])


def _params(sizes: list[int]) -> int:
    """Weights and biases of an MLP with layer sizes ``sizes`` (input, hidden…, output)."""
    return sum((a + 1) * b for a, b in zip(sizes, sizes[1:]))


def _arch(hp: dict[str, Any], key: str, default: list[int]) -> list[int]:
    """The hidden layers of network ``key`` (``pi``, ``vf``, ``qf``) of ``policy_kwargs.net_arch``."""
    arch = (hp.get("policy_kwargs") or {}).get("net_arch", default)
    return list(arch.get(key, default) if isinstance(arch, dict) else arch)


_BUFFER_FIELD = {"ppo": "n_steps", "rsl-ppo": "num_steps_per_env", "sac": "buffer_size", "td3": "buffer_size"}
"""The field that sizes each algorithm's rollout or replay buffer (named when the buffer is too large)."""


def predicted_bytes(algo: str, hp: dict[str, Any], obs: int, act: int) -> tuple[int, int]:
    """(buffer, networks): the memory a run of ``algo`` with the (checked) hyperparameters ``hp`` allocates for
    itself, predicted in bytes. The buffer: PPO's rollout of n_steps × n_envs transitions, rsl-ppo's of
    num_steps_per_env × n_envs, SAC's and TD3's replay buffer of buffer_size transitions (observations stored
    twice); float32 throughout. The networks: weights with their gradients and Adam's two moments (× 4; the
    off-policy target networks once more)."""
    f32 = 4
    if algo == "ppo":
        rollout = int(hp.get("n_steps", 2048)) * int(hp["n_envs"]) * (obs + act + 6)
        nets = _params([obs, *_arch(hp, "pi", [64, 64]), act]) + _params([obs, *_arch(hp, "vf", [64, 64]), 1])
        return f32 * rollout, f32 * 4 * nets
    if algo == "rsl-ppo":
        rollout = int(hp["num_steps_per_env"]) * int(hp["n_envs"]) * (obs + 3 * act + 6)
        hidden = list(hp["hidden_dims"])
        return f32 * rollout, f32 * 4 * (_params([obs, *hidden, act]) + _params([obs, *hidden, 1]))
    default = [256, 256] if algo == "sac" else [400, 300]
    replay = int(hp.get("buffer_size", 1_000_000)) * (2 * obs + act + 3)
    critics = int((hp.get("policy_kwargs") or {}).get("n_critics", 2))
    actor = _params([obs, *_arch(hp, "pi", default), 2 * act if algo == "sac" else act])
    critic = critics * _params([obs + act, *_arch(hp, "qf", default), 1])
    return f32 * replay, f32 * 5 * (actor + critic)


def _collection(algo: str, hp: dict[str, Any]) -> tuple[int, str]:
    """(steps, field): the environment steps a trainer collects between two looks at its budget (PPO's rollout,
    rsl-ppo's iteration, SAC's and TD3's n_envs × train_freq) and the field that sets it."""
    nenv = hp["n_envs"]
    if algo == "ppo":
        return nenv * hp.get("n_steps", 2048), "n_steps"
    if algo == "rsl-ppo":
        return nenv * hp["num_steps_per_env"], "num_steps_per_env"
    freq = hp.get("train_freq", 1)
    return nenv * (
        freq[0] if isinstance(freq, list) and freq[1] == "step" else 1 if isinstance(freq, list) else freq
    ), "train_freq"


def check_hyperparams(algo: str, hp: Any, env_id: str, *, where: str = "hyperparams") -> dict[str, Any]:
    """``hp`` checked for ``algo`` on ``env_id``: every field (:data:`FIELDS`), the combinations of fields, the task's
    keywords (``env_kwargs``) and the memory the run is predicted to allocate (:func:`predicted_bytes`, at most
    :data:`~flatbody_env.physics.validation.MAX_TRAINER_BYTES`). Returns the checked values (numbers as numbers: YAML
    1.1's ``3e-4`` string is the float 3e-4). ``ValueError`` naming ``<where>.<field>``."""
    check_algo(algo)
    hp = validation.fields(where, hp, FIELDS[algo])
    for key in ("n_timesteps", "n_envs"):
        if key not in hp:
            raise ValueError(f"{where}.{key}: missing field")
    req = validation.requirement
    nenv, total = hp["n_envs"], hp["n_timesteps"]
    if algo == "ppo":
        rollout = hp.get("n_steps", 2048) * nenv
        batch = hp.get("batch_size", 64)
        req(f"{where}.n_steps", hp.get("n_steps", 2048), rollout > 1, "give n_steps x n_envs > 1 (PPO needs two steps)")
        req(f"{where}.batch_size", batch, batch <= rollout, f"be at most n_steps x n_envs = {rollout}")
        req(
            f"{where}.batch_size",
            batch,
            rollout % batch == 0,
            f"divide n_steps x n_envs = {rollout} (whole minibatches)",
        )
    elif algo in ("sac", "td3"):
        buffer = hp.get("buffer_size", 1_000_000)
        req(f"{where}.buffer_size", buffer, buffer >= nenv, f"be at least n_envs = {nenv} (one row per env)")
        req(f"{where}.batch_size", hp.get("batch_size", 256), hp.get("batch_size", 256) <= buffer,
            f"be at most buffer_size = {buffer}")  # fmt: skip
        starts = hp.get("learning_starts", 100)
        req(f"{where}.learning_starts", starts, starts < total,
            f"be below n_timesteps = {total} (else the run never trains)")  # fmt: skip
        req(f"{where}.gradient_steps", hp.get("gradient_steps", 1), hp.get("gradient_steps", 1) != 0,
            "be -1 (as many as steps collected) or >= 1")  # fmt: skip
        if "noise_std" in hp:
            req(f"{where}.noise_std", hp["noise_std"], hp.get("noise_type") is not None, "come with a noise_type")
    else:  # rsl-ppo
        missing = sorted(set(RSL_DEFAULTS) - set(hp))
        if missing:
            raise ValueError(f"{where}.{missing[0]}: missing field")
        rollout = hp["num_steps_per_env"] * nenv
        req(f"{where}.num_mini_batches", hp["num_mini_batches"], hp["num_mini_batches"] <= rollout,
            f"be at most num_steps_per_env x n_envs = {rollout} (a minibatch holds at least one transition)")  # fmt: skip
    if hp.get("residual") is None:
        for key in ("residual_mode", "residual_scale", "residual_gate"):
            if key in hp and algo != "rsl-ppo":
                req(f"{where}.{key}", hp[key], False, "come with a residual (heuristic or passivity)")
    unit, name = _collection(algo, hp)
    req(f"{where}.{name}", hp.get(name), unit <= 2 * total,
        f"keep one collection ({unit} steps) within twice n_timesteps = {total} (it trains whole collections)")  # fmt: skip
    obs, act = _dims(env_id, dict(hp.get("env_kwargs") or {}), where)
    buffer, nets = predicted_bytes(algo, hp, obs, act)
    name = _BUFFER_FIELD[algo] if buffer >= nets else ("hidden_dims" if algo == "rsl-ppo" else "policy_kwargs.net_arch")
    validation.memory(f"{where}.{name}", buffer + nets, "the run's buffers and networks")
    return hp


@dataclass(frozen=True, kw_only=True)
class RunConfig:
    """Everything a training run needs to be continued or trained again, as its folder's ``config.yml`` holds it.

    Attributes
    ----------
    algo : str
        :data:`ALGOS`.
    env_id : str
        A registered id (docs/tasks.md); its version is :attr:`env_version`.
    seed : int
        The training seed (environments, networks, exploration).
    hyperparams : dict
        The checked hyperparameters after overrides (:func:`check_hyperparams`), ``n_timesteps`` (the budget),
        ``n_envs`` and ``env_kwargs`` (the task's keywords over its registered ones) among them.
    device : str
        The torch device (:data:`DEVICES`).
    trained_agent : str, optional
        Fine-tuning: the run folder whose model the run starts from (a prior).
    curriculum : dict, optional
        The curriculum over one task keyword (:mod:`agents.curriculum`; a prior).
    imitation : dict, optional
        A policy cloned from plans (``flatbody imitate clone``; a prior): the plans files and the fit's settings.
    source : dict
        Where the hyperparameters came from: the file, its entry and the overrides (information only).
    """

    algo: str
    env_id: str
    seed: int = 0
    hyperparams: dict[str, Any] = field(default_factory=dict)
    device: str = "cpu"
    trained_agent: str | None = None
    curriculum: dict[str, Any] | None = None
    imitation: dict[str, Any] | None = None
    source: dict[str, Any] = field(default_factory=dict)

    @property
    def n_timesteps(self) -> int:
        """The budget: environment steps the run trains in all."""
        return int(self.hyperparams["n_timesteps"])

    @property
    def n_envs(self) -> int:
        return int(self.hyperparams["n_envs"])

    @property
    def env_kwargs(self) -> dict[str, Any]:
        """The task's keywords over its registered ones (``hyperparams.env_kwargs``)."""
        return dict(self.hyperparams.get("env_kwargs") or {})

    @property
    def env_version(self) -> int:
        from flatbody_env.env.registration import task_spec

        return task_spec(self.env_id).version

    @property
    def model_format(self) -> str:
        """The SB3 class of the run's ``model.zip`` (:data:`MODEL_FORMATS`)."""
        return "ppo" if self.algo == "rsl-ppo" else self.algo

    @property
    def prior(self) -> dict[str, Any] | None:
        """What the run starts from beside its own policy — a controller residual, a model to fine-tune, a curriculum —
        or None: from scratch."""
        prior = {
            "residual": self.hyperparams.get("residual"),
            "trained_agent": self.trained_agent,
            "curriculum": self.curriculum,
            "imitation": self.imitation,
        }
        prior = {k: v for k, v in prior.items() if v is not None}
        return prior or None

    def replace(self, **changes: Any) -> RunConfig:
        return replace(self, **changes)

    def mapping(self) -> dict[str, Any]:
        """The ``config.yml`` of the run (format :data:`CONFIG_FORMAT`)."""
        return {
            "format": CONFIG_FORMAT,
            "algo": self.algo,
            "env_id": self.env_id,
            "env_version": self.env_version,
            "seed": self.seed,
            "device": self.device,
            "n_timesteps": self.n_timesteps,
            "model_format": self.model_format,
            "prior": self.prior,
            "hyperparams": copy.deepcopy(self.hyperparams),
            "source": copy.deepcopy(self.source),
        }

    @classmethod
    def from_mapping(cls, cfg: Any, *, where: str = "config.yml") -> RunConfig:
        """The configuration a ``config.yml`` holds (this format or the shipped v0 agents' format 1), checked as a new
        run's is; ``ValueError`` naming ``<where>.<field>``."""
        from flatbody_env.env.registration import task_spec

        validation.mapping(where, cfg)
        fmt = cfg.get("format", 1)
        validation.field(f"{where}.format", fmt, Field(kind=_C, choices=(1, CONFIG_FORMAT)))
        algo = cfg.get("algo")
        trainer = cfg.get("trainer")
        if fmt == 1 and isinstance(trainer, dict) and trainer.get("name") == "rsl-ppo":
            algo = "rsl-ppo"  # format 1 named the model file's format (ppo) and the trainer apart
        algo = check_algo(algo, f"{where}.algo")
        env_id = validation.string(f"{where}.env_id", cfg.get("env_id"))
        try:
            task_spec(env_id)
        except ValueError as exc:
            raise ValueError(f"{where}.{exc}") from None
        seed = validation.integer(f"{where}.seed", cfg.get("seed", 0), low=0, high=validation.MAX_SEED)
        device = validation.field(f"{where}.device", cfg.get("device", "cpu"), Field(kind=_C, choices=DEVICES))
        hp = cfg.get("hyperparams")
        if algo == "rsl-ppo" and isinstance(hp, dict):
            hp = {**copy.deepcopy(RSL_DEFAULTS), **hp}
        hp = check_hyperparams(algo, hp, env_id, where=f"{where}.hyperparams")
        prior = cfg.get("prior") if fmt != 1 else cfg
        prior = validation.mapping(f"{where}.prior", prior) if prior is not None else {}
        trained = prior.get("trained_agent")
        if trained is not None:
            validation.string(f"{where}.prior.trained_agent", trained)
        curriculum = prior.get("curriculum")
        if curriculum is not None:
            curriculum = validation.fields(f"{where}.prior.curriculum", curriculum, CURRICULUM_FIELDS)
        imitation = prior.get("imitation")
        if imitation is not None:
            imitation = dict(validation.mapping(f"{where}.prior.imitation", imitation))
        source = cfg.get("source") or {}
        return cls(
            algo=algo,
            env_id=env_id,
            seed=seed,
            hyperparams=hp,
            device=device,
            trained_agent=trained,
            curriculum=curriculum,
            imitation=imitation,
            source=dict(validation.mapping(f"{where}.source", source)),
        )

    @classmethod
    def read(cls, path: str | Path, *, where: str = "config") -> RunConfig:
        """The configuration of a run folder (its ``config.yml``) or of a ``config.yml`` file, read through the one
        reading door (:func:`agents.numpy_policy.read_run_config`: bounded, no alias expansion)."""
        from agents.numpy_policy import read_run_config

        p = Path(path)
        folder = p if p.is_dir() else p.parent
        if not p.is_dir() and p.name != "config.yml":
            validation.requirement(where, str(p)[:80], False, "name a run folder or its config.yml")
        if not (folder / "config.yml").is_file():
            raise ValueError(f"{where}: no config.yml in {str(folder)[:80]!r} (not a run folder)")
        return cls.from_mapping(read_run_config(folder))


CURRICULUM_FIELDS: dict[str, Field] = {
    "key": Field(kind="string"),
    "stages": Field(kind="numbers", low=-1e6, high=1e6),
    "advance_at": Field(kind=_N, low=0.0, high=1.0),
    "min_stage_steps": Field(kind=_I, low=0, high=validation.MAX_TIMESTEPS),
    "max_stage_steps": Field(kind=_I, low=1, high=validation.MAX_TIMESTEPS),
    "window": Field(kind=_I, low=1, high=10_000),
    "train_env_kwargs": Field(kind="mapping", nullable=True),
    "log_std_per_action": Field(kind="numbers", low=-20.0, high=2.0, nullable=True),
    "history": Field(kind="list", max_items=1000, nullable=True),
}
"""The curriculum of a run (:func:`agents.curriculum.curriculum_callback`'s settings; ``history`` is what a run did)."""


def resolve(
    algo: str,
    env_id: str = DEFAULT_ENV_ID,
    *,
    seed: int = 0,
    n_timesteps: int | None = None,
    n_envs: int | None = None,
    overrides: list[str] | None = None,
    hyperparams_file: str | Path | None = None,
    device: str = "cpu",
    trained_agent: str | Path | None = None,
    curriculum: dict[str, Any] | None = None,
) -> RunConfig:
    """The checked :class:`RunConfig` of a new run: the file entry of ``env_id`` (:func:`load_hyperparams`), then the
    overrides, then ``n_timesteps`` and ``n_envs`` (the flags), each checked the same way."""
    from flatbody_env.env.registration import task_spec

    check_algo(algo)
    task_spec(env_id)  # ValueError naming env for an id that is not a registered task
    validation.integer("seed", seed, low=0, high=validation.MAX_SEED)
    hp = apply_overrides(load_hyperparams(algo, env_id, hyperparams_file), overrides or [])
    if n_timesteps is not None:
        hp["n_timesteps"] = validation.integer("n_timesteps", n_timesteps, low=1, high=validation.MAX_TIMESTEPS)
    if n_envs is not None:
        hp["n_envs"] = validation.integer("n_envs", n_envs, low=1, high=validation.MAX_BATCH)
    hp = check_hyperparams(algo, hp, env_id)
    file = Path(hyperparams_file) if hyperparams_file else hyperparams_path(algo)
    return RunConfig(
        algo=algo,
        env_id=env_id,
        seed=seed,
        hyperparams=hp,
        device=validation.field("device", device, Field(kind=_C, choices=DEVICES)),
        trained_agent=str(trained_agent) if trained_agent is not None else None,
        curriculum=curriculum,
        source={
            "file": shown_path(file, Path(__file__).resolve().parent.parent),
            "entry": env_id,
            "overrides": list(overrides or []),
        },
    )


POLICY_FORM = (
    "policy",
    "policy_kwargs",
    "use_sde",
    "normalize",
    "residual",
    "residual_mode",
    "residual_scale",
    "residual_gate",
)
"""The hyperparameters that say what a policy's numbers mean — its network, observation statistics and the law its action
adds to — which a fine-tuning run (``trained_agent``) takes from the run it starts from (:func:`fine_tuning`)."""


def fine_tuning(config: RunConfig) -> RunConfig:
    """``config`` with :data:`POLICY_FORM` taken from its ``trained_agent``'s ``config.yml`` (unchanged without a trained
    agent, or where that folder has no ``config.yml``): the loaded weights act as they were trained — a residual on
    the pumping law stays one — and ``config.yml`` names the network that is trained. The rollout and update settings
    stay the run's own. ``ValueError`` naming ``trained_agent`` for another algorithm (or rsl-ppo: it does not
    fine-tune), naming ``hyperparams.KEY`` where an override (``source.overrides``) sets one of those keys otherwise."""
    if config.trained_agent is None:
        validation.requirement(
            "hyperparams.fine_tune_log_std",
            config.hyperparams.get("fine_tune_log_std"),
            "fine_tune_log_std" not in config.hyperparams,
            "come with a trained agent (--trained-agent); a new run's is policy_kwargs.log_std_init",
        )
        return config
    if config.algo not in SB3_ALGOS:
        raise ValueError(f"trained_agent: {config.algo} does not fine-tune a trained agent (ppo, sac and td3 do)")
    path = Path(config.trained_agent) / "config.yml"
    if not path.is_file():
        return config
    try:
        trained = RunConfig.read(path, where="trained_agent")
    except ValueError as exc:  # its config.yml is not a run's: say whose it is
        raise ValueError(f"trained_agent: {str(config.trained_agent)[:80]!r}: {exc}") from None
    if trained.algo != config.algo:
        raise ValueError(
            f"trained_agent: {str(config.trained_agent)[:80]!r} is a {trained.algo} run; it fine-tunes with "
            f"--algo {trained.algo}, not {config.algo}"
        )
    overridden = {str(item).split("=", 1)[0].strip().split(".")[0] for item in config.source.get("overrides") or []}
    hp = copy.deepcopy(config.hyperparams)
    for key in POLICY_FORM:
        ours, theirs = hp.get(key), trained.hyperparams.get(key)
        if key in overridden and ours != theirs:
            raise ValueError(
                f"hyperparams.{key}: the trained agent {str(config.trained_agent)[:80]!r} has {theirs!r}; a fine-tuning "
                f"run keeps its policy's form (got {str(ours)[:80]!r})"
            )
        if key in trained.hyperparams:
            hp[key] = copy.deepcopy(theirs)
        else:
            hp.pop(key, None)
    return config.replace(hyperparams=check_hyperparams(config.algo, hp, config.env_id))


__all__ = [
    "ACTIVATIONS",
    "ALGOS",
    "CONFIG_FORMAT",
    "CURRICULUM_FIELDS",
    "DEFAULT_ENV_ID",
    "DEVICES",
    "FIELDS",
    "HYPERPARAMS_DIR",
    "MODEL_FORMATS",
    "POLICY_FORM",
    "RSL_DEFAULTS",
    "RunConfig",
    "SB3_ALGOS",
    "apply_overrides",
    "check_algo",
    "check_device",
    "checked_env_kwargs",
    "check_hyperparams",
    "fine_tuning",
    "hyperparams_path",
    "load_hyperparams",
    "parse_env_kwargs",
    "predicted_bytes",
    "resolve",
]
