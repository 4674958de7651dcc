"""A trained agent's deterministic policy as plain numpy: no torch, no Stable-Baselines3 at run time.

``flatbody export-policy [MODEL]`` (:func:`export_policy`) reads the SB3 model (``model.zip``) and
its VecNormalize statistics (``vecnormalize.pkl``) once, with torch, and writes
``policy.npz`` beside them. :class:`NumpyPolicy` evaluates it with numpy alone; ``flatbody demo``
and ``flatbody evaluate`` use it (:class:`agents.evaluate.Agent`), so they never import torch.

What is exported (the deterministic action SB3's ``predict(obs, deterministic=True)`` returns):

* the observation normalisation of VecNormalize: clip((o − mean)/√(var + ε), −clip, clip)
  (when the run normalised observations);
* the actor's MLP (``mlp_extractor.policy_net`` of an actor-critic policy, ``actor.latent_pi``
  of SAC), as (W, b) per linear layer and the activation between them (tanh, ReLU or ELU);
* the action head (``action_net`` of PPO/A2C: the mean action, also with gSDE; ``actor.mu`` of
  SAC), then SB3's post-processing: tanh squashing and unscaling to the action bounds for a
  squashed policy (SAC), clipping to the bounds otherwise.

The file is versioned (:data:`FORMAT_VERSION`) and records the SHA-256 of ``model.zip`` and
``vecnormalize.pkl`` it was made from. :func:`load_policy` refuses a file whose checksums no longer
match (a retrained or replaced model), so a model is never evaluated with stale weights; re-export
is one command. SB3 computes in float32, this evaluator in float64: the actions agree to ≈1e-7
(tested to 1e-6).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

FORMAT_VERSION = 1
"""Version of the ``policy.npz`` layout; a file of another version is refused (re-export it)."""
POLICY_FILE = "policy.npz"
MAX_POLICY_BYTES = 64 * 1024 * 1024
"""Largest ``policy.npz``, and most bytes its arrays may declare (an MLP of 2 000 × 2 000 float64 layers)."""


def _expm1(v: np.ndarray) -> np.ndarray:
    """e^v − 1 as the C library computes it (:mod:`flatbody_env.integrators.libm`: NumPy's differs in the last bit on
    AVX-512 machines); imported on first use, so that reading this module's constants loads no compiler."""
    from flatbody_env.integrators.libm import expm1

    return expm1(v)


_ACTIVATION_FUNCTIONS = {
    "tanh": np.tanh,
    "relu": lambda v: np.maximum(v, 0.0),
    "elu": lambda v: np.where(v > 0.0, v, _expm1(np.minimum(v, 0.0))),
}
ACTIVATIONS = tuple(_ACTIVATION_FUNCTIONS)
"""The activations between linear layers that an exported policy may have (ELU with α = 1, rsl_rl's default)."""
MODELS_DIR = Path(__file__).resolve().parent / "models"
"""Where shipped agents live: ``MODELS_DIR/<algo>-<env id>/`` (model.zip, config.yml, ...); also :data:`agents.evaluate.MODELS_DIR`."""


SHIPPED_AGENT = "rsl-ppo-FlatBody-v1"
"""The agent ``demo``, ``evaluate`` and ``record --agent`` run by default: rsl_rl's PPO trained from scratch on
``FlatBody-v1`` with the registered reward and the entry of ``agents/hyperparams/rsl-ppo.yml`` (its ``config.yml``
trains it again). The other folders of :data:`MODELS_DIR` are the prior track's agents of the v0 ids."""


def shipped_model_dir() -> Path:
    """The folder of the agent shipped in the package (``agents/models/`` :data:`SHIPPED_AGENT`); also
    :func:`agents.evaluate.shipped_model_dir`."""
    return MODELS_DIR / SHIPPED_AGENT


class StalePolicyError(ValueError):
    """``policy.npz`` is missing, of another format version, or was exported from other files."""


class DamagedPolicyError(ValueError):
    """``policy.npz`` is there but cannot be read (truncated, not an npz, pickled content, wrong arrays):
    an error, never a silent fall-back to the pickled model."""


# -- trust: what may be unpickled (docs/reliability.md, "Trust model") ---------------------------------
_TRUST = {"required": False}


def require_trust(required: bool = True) -> None:
    """Set whether loading a pickle (SB3 ``model.zip``, ``vecnormalize.pkl``, checkpoints) needs the
    folder to be trusted (:func:`trusted`). The CLI turns it on unless ``--trust`` is given; the
    Python API leaves it off (the caller names the paths in code)."""
    _TRUST["required"] = bool(required)


class trust_policy:
    """Context manager: :func:`require_trust` (``required``) inside, the previous setting restored after
    (the CLI wraps each command that loads a model in it)."""

    def __init__(self, required: bool) -> None:
        self.required = bool(required)

    def __enter__(self) -> Self:
        self._old = _TRUST["required"]
        _TRUST["required"] = self.required
        return self

    def __exit__(self, *exc) -> None:
        _TRUST["required"] = self._old


MAX_MODEL_BYTES = 1 << 30
"""Largest pickle-based file read (``model.zip``, ``vecnormalize.pkl``, a checkpoint, a replay buffer), through
:func:`flatbody_env.physics.validation.read_bytes` like every other file."""


def _trust_file() -> Path:
    import os

    base = os.environ.get("FLATBODY_CONFIG_HOME") or os.path.join(
        os.environ.get("XDG_CONFIG_HOME") or os.path.expanduser("~/.config"), "flatbody"
    )
    return Path(base) / "trusted-runs.txt"


def _homes() -> set[Path]:
    """The user's home folder, as ``$HOME`` and as the password database give it."""
    import os

    homes = {Path(os.path.expanduser("~"))}
    try:
        import pwd

        homes.add(Path(pwd.getpwuid(os.getuid()).pw_dir))
    except (ImportError, KeyError, OSError):
        pass
    return {h.resolve() for h in homes if str(h) and h.is_absolute()}


def trust_refusal(folder: str | Path) -> str | None:
    """Why ``folder`` can never be trusted (None: it can be): the root folder, the user's home folder or a folder
    above it (trusting one would trust every pickle below it), or a path with a line break (the list of trusted
    folders holds one per line)."""
    text = str(folder)
    if any(c in text for c in "\n\r\0"):
        return "holds a line break or NUL"
    f = Path(folder).resolve()
    if f == Path(f.anchor):
        return "is the root folder"
    if any(f == h or f in h.parents for h in _homes()):
        return "is your home folder or a folder above it"
    return None


def trusted_roots() -> list[Path]:
    """Folders whose pickles load without ``--trust``: the shipped agents (``agents/models``), the run
    folders this user's runs have written to (:func:`remember_run`) and the folders listed in
    ``$FLATBODY_TRUSTED_DIRS`` (``os.pathsep``-separated). A listed folder that can never be trusted
    (:func:`trust_refusal`: ``/``, the home folder or above) or is not an absolute path is ignored."""
    import os

    from flatbody_env.physics import validation

    listed = [x for x in os.environ.get("FLATBODY_TRUSTED_DIRS", "").split(os.pathsep) if x.strip()]
    with contextlib.suppress(ValueError):  # the one reading door: a regular file of bounded size (never a FIFO)
        listed += validation.read_text("trusted-runs", _trust_file(), max_bytes=validation.MAX_TEXT_BYTES).splitlines()
    roots = [MODELS_DIR.resolve()]
    for line in listed:
        p = Path(line.strip()).expanduser()
        if line.strip() and p.is_absolute() and trust_refusal(p) is None:
            roots.append(p.resolve())
    return roots


def trusted(folder: str | Path) -> bool:
    """Whether ``folder`` (or a file) lies in one of :func:`trusted_roots`, its links resolved."""
    f = Path(folder).resolve()
    return any(f == r or r in f.parents for r in trusted_roots())


def remember_run(folder: str | Path) -> bool:
    """Record ``folder`` as one of this user's run folders, so that its pickles load later without ``--trust``.

    Called by the code that writes a run's first file, once that file is in place (``config.yml`` of
    ``flatbody train``, of ``python -m agents.imitation clone``): a run refused before it wrote anything
    trusts nothing. Returns whether the folder is trusted now; a list that cannot be written (a read-only
    configuration folder, a link planted in its place) is a note on stderr, not an error of the run.

    Raises
    ------
    ValueError
        Naming ``out`` when the folder can never be trusted (:func:`trust_refusal`).
    """
    import sys

    from flatbody_env.output import OutputError, append_line

    reason = trust_refusal(folder)
    if reason is not None:
        raise ValueError(
            f"out: {str(folder)[:80]!r} {reason}, so it is never trusted; give the run a folder of its own"
        )
    f = Path(folder).resolve()
    if trusted(f):
        return True
    path = _trust_file()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        append_line(path, str(f))
    except (OSError, OutputError) as exc:
        sys.stderr.write(
            f"flatbody: note: {str(f)[:80]!r} not recorded as trusted ({' '.join(str(exc).split())[:160]}); "
            "its model loads with --trust\n"
        )
        return False
    return True


def check_trusted(folder: str | Path, what: str, where: str = "model") -> None:
    """The one trust check: refuse (``ValueError`` naming ``where``) to unpickle ``what`` from ``folder`` (a folder or
    a file; links resolved) outside :func:`trusted_roots` while :func:`require_trust` is on."""
    if _TRUST["required"] and not trusted(folder):
        raise ValueError(
            f"{where}: loading {what} from {str(folder)[:80]!r} unpickles it, which can run arbitrary code, and it is "
            "neither the shipped agent nor one of your runs (flatbody train, sweep); pass --trust if you trust its source "
            "(docs/reliability.md, Trust model)"
        )


def read_pickled(path: str | Path, what: str, where: str = "model") -> bytes:
    """The bytes of a pickle-based file (``model.zip``, ``vecnormalize.pkl``, a checkpoint, a replay buffer), through
    the one trust check (:func:`check_trusted`, on the file itself) and the one reading door (a regular file of at most
    :data:`MAX_MODEL_BYTES`; a FIFO or device is refused). Every unpickling in the package starts here
    (:func:`load_sb3`, :func:`load_vecnormalize`, :func:`load_replay_buffer`)."""
    from flatbody_env.physics import validation

    check_trusted(path, what, where)
    return validation.read_bytes(where, path, max_bytes=MAX_MODEL_BYTES)


def sha256(path: Path, where: str = "model") -> str:
    """SHA-256 of a file read through the one reading door (a regular file of at most :data:`MAX_MODEL_BYTES`)."""
    from flatbody_env.physics import validation

    return hashlib.sha256(validation.read_bytes(where, path, max_bytes=MAX_MODEL_BYTES)).hexdigest()


def _sources(folder: Path) -> dict[str, str | None]:
    """Checksums of the files a policy is exported from (None: absent)."""
    vn = folder / "vecnormalize.pkl"
    return {"model.zip": sha256(folder / "model.zip"), "vecnormalize.pkl": sha256(vn) if vn.exists() else None}


def model_folder(path: str | Path | None) -> Path:
    """The run folder of ``path`` (a folder with ``model.zip`` or the ``model.zip`` itself; None: the shipped agent)."""
    if path is None:
        return shipped_model_dir()
    p = Path(path)
    folder = p if p.is_dir() else p.parent
    if p.is_file() and p.name != "model.zip":
        raise ValueError(f"model: the exported policy is read beside a file named model.zip, got {str(p)!r}")
    if not (folder / "model.zip").exists():
        raise ValueError(f"model: no model at {str(p)!r} (expected a run folder with model.zip, or a model.zip)")
    return folder


def read_run_config(folder: Path) -> dict:
    """A run folder's ``config.yml`` (safe YAML) as a mapping ({} when absent); a damaged or non-mapping
    file, or a non-mapping ``hyperparams`` / ``env_kwargs``, is a ``ValueError`` naming ``config.yml``."""
    from flatbody_env.physics import validation

    cfg_file = Path(folder) / "config.yml"
    if not cfg_file.exists():
        return {}
    config = validation.read_yaml("config.yml", cfg_file)  # the one reading door: bounded, no alias bombs
    if config is None:
        return {}
    if not isinstance(config, dict):
        raise ValueError(
            f"config.yml: {str(cfg_file)[:80]!r} must hold a mapping (algo, env_id, hyperparams), got a {type(config).__name__}"
        )
    hp = config.get("hyperparams")
    validation.requirement("config.yml.hyperparams", hp, hp is None or isinstance(hp, dict), "be a mapping")
    if hp and hp.get("env_kwargs") is not None:
        env_kwargs = hp["env_kwargs"]
        validation.requirement(
            "config.yml.hyperparams.env_kwargs", env_kwargs, isinstance(env_kwargs, dict), "be a mapping"
        )
    for key in ("algo", "env_id"):
        if config.get(key) is not None:
            validation.string(f"config.yml.{key}", config[key])
    return config


MODEL_FORMATS = ("ppo", "sac", "td3")
"""The SB3 classes a ``model.zip`` is saved as (:data:`agents.config.MODEL_FORMATS`)."""


def model_format_of(config: dict, model_name: str = "model.zip") -> str:
    """The SB3 class (:data:`MODEL_FORMATS`) of a run's ``model.zip`` as its ``config.yml`` (``config``) says: its
    ``model_format``; in the format of the shipped v0 agents its ``algo`` (rsl-ppo's actor is an SB3 PPO model); a
    run without config.yml by the file's name (``sac`` in it: SAC). ``ValueError`` naming ``config.yml``."""
    from flatbody_env.physics import validation

    fmt = config.get("model_format")
    if fmt is None:
        algo = config.get("algo") or ("sac" if "sac" in model_name.lower() else "ppo")
        fmt = "ppo" if algo == "rsl-ppo" else algo
        return validation.string("config.yml.algo", fmt, choices=MODEL_FORMATS)
    return validation.string("config.yml.model_format", fmt, choices=MODEL_FORMATS)


def load_sb3(
    cls, model_file: Path, *, where: str = "model", what: str = "model.zip (a pickle-based SB3 file)", **kwargs
):
    """``cls.load`` of ``model_file`` on the CPU, read through :func:`read_pickled` (trusted folders only, a regular
    file); a file SB3 cannot read (empty, truncated, not a model) is a one-line ``ValueError`` naming ``where``.
    ``kwargs`` go to ``cls.load`` (``env``, ``custom_objects``)."""
    import io

    data = read_pickled(model_file, what, where)
    try:
        if not data:
            raise ValueError("the file is empty")
        return cls.load(io.BytesIO(data), device="cpu", **kwargs)
    except Exception as exc:  # noqa: BLE001 - zipfile.BadZipFile, KeyError, pickle errors, RuntimeError of torch.load
        raise ValueError(
            f"{where}: cannot load {str(model_file)[:80]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None


def load_vecnormalize(path: Path, venv=None, *, where: str = "model"):
    """The ``VecNormalize`` statistics pickled in ``path`` (read through :func:`read_pickled`), wrapped around ``venv``
    when given (SB3's ``VecNormalize.load``); a file that does not unpickle into one is a ``ValueError`` naming ``where``."""
    import pickle

    data = read_pickled(path, "vecnormalize.pkl (a pickle)", where)
    try:
        from stable_baselines3.common.vec_env import VecNormalize

        vn = pickle.loads(data)
        if not isinstance(vn, VecNormalize):
            raise TypeError(f"it holds a {type(vn).__name__}, not VecNormalize statistics")
        if venv is not None:
            vn.set_venv(venv)
        return vn
    except Exception as exc:  # noqa: BLE001 - truncated or foreign pickle
        raise ValueError(
            f"{where}: cannot load {str(path)[:80]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None


def load_replay_buffer(model, path: Path, *, where: str = "resume") -> None:
    """SAC's replay buffer pickled in ``path`` into ``model`` (read through :func:`read_pickled`)."""
    import io

    data = read_pickled(path, "the replay buffer (a pickle)", where)
    try:
        model.load_replay_buffer(io.BytesIO(data))
    except Exception as exc:  # noqa: BLE001 - truncated or foreign pickle
        raise ValueError(
            f"{where}: cannot load {str(path)[:80]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None


def load_torch_state(path: Path, *, where: str = "resume", map_location=None) -> dict:
    """A torch checkpoint's state (rsl-ppo's ``rsl_model_N_steps.pt``: tensors and plain data), read through
    :func:`read_pickled` and unpickled by ``torch.load(weights_only=True)`` (no code objects even then); a file that does
    not load into a mapping is a ``ValueError`` naming ``where``."""
    import io

    import torch

    data = read_pickled(path, "a checkpoint (a torch file)", where)
    try:
        state = torch.load(io.BytesIO(data), weights_only=True, map_location=map_location)
        if not isinstance(state, dict):
            raise TypeError(f"it holds a {type(state).__name__}, not a mapping")
        return state
    except Exception as exc:  # noqa: BLE001 - truncated or foreign file
        raise ValueError(
            f"{where}: cannot load {str(path)[:80]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None


@dataclass(frozen=True)
class NumpyPolicy:
    """The deterministic policy of an exported agent: raw observations (N, 16) → actions (N, n) float32."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    activation: str
    obs_mean: np.ndarray | None
    obs_scale: np.ndarray | None
    clip_obs: float
    squash: bool
    low: np.ndarray
    high: np.ndarray
    meta: dict

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """VecNormalize's frozen observation normalisation (identity when the run did not normalise)."""
        o = np.asarray(obs, dtype=np.float64)
        if self.obs_mean is None:
            return o
        return np.clip((o - self.obs_mean) / self.obs_scale, -self.clip_obs, self.clip_obs)

    def forward(self, normalized_obs: np.ndarray) -> np.ndarray:
        """The action head's output (before squashing/clipping) for normalised observations (N, d)."""
        x = np.atleast_2d(np.asarray(normalized_obs, dtype=np.float64))
        act = _ACTIVATION_FUNCTIONS[self.activation]
        last = len(self.weights) - 1
        for k, (W, b) in enumerate(zip(self.weights, self.biases)):
            x = x @ W.T + b
            if k < last:
                x = act(x)
        return x

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        a = self.forward(self.normalize(obs))
        if self.squash:
            a = self.low + 0.5 * (np.tanh(a) + 1.0) * (self.high - self.low)
        else:
            a = np.clip(a, self.low, self.high)
        return a.astype(np.float32)


def export_policy(path: str | Path | None = None) -> Path:
    """Write ``policy.npz`` beside the SB3 model at ``path`` (default: the shipped agent); returns its path.

    Imports torch and SB3 (this is the one step that needs them). ValueError for a model whose
    policy is not an MLP of linear layers with tanh, ReLU or ELU (the only kinds this evaluator runs).
    """
    folder = model_folder(path)
    algo = model_format_of(read_run_config(folder))
    check_trusted(folder, "model.zip and vecnormalize.pkl")
    import torch
    from stable_baselines3 import PPO, SAC, TD3

    torch.set_num_threads(1)
    sources = _sources(folder)
    model = load_sb3({"ppo": PPO, "sac": SAC, "td3": TD3}[algo], folder / "model.zip")
    policy = model.policy
    if algo == "sac":
        trunk, head = policy.actor.latent_pi, policy.actor.mu
    elif algo == "td3":  # mu = MLP ending in tanh: the tanh is the squashing of the export (squash below)
        layers = list(policy.actor.mu)
        if not layers or not isinstance(layers[-1], torch.nn.Tanh):
            raise ValueError("model: a TD3 actor whose last layer is not tanh cannot be exported")
        trunk, head = torch.nn.Sequential(*layers[:-1]), torch.nn.Sequential()
    else:
        trunk, head = policy.mlp_extractor.policy_net, policy.action_net
    names = {torch.nn.Tanh: "tanh", torch.nn.ReLU: "relu", torch.nn.ELU: "elu"}
    layers, activations = [], set()

    def flat(module):  # nested Sequentials (SB3 builds some MLPs that way) in order
        if isinstance(module, torch.nn.Sequential):
            return [leaf for child in module for leaf in flat(child)]
        return [module]

    for module in flat(trunk) + flat(head):
        if isinstance(module, torch.nn.Linear):
            # stored in the layer's own precision (float32: half the file, and exact — the forward pass
            # computes in float64 whatever the stored dtype)
            layers.append((module.weight.detach().cpu().numpy().copy(), module.bias.detach().cpu().numpy().copy()))
        elif type(module) in names and getattr(module, "alpha", 1.0) == 1.0:
            activations.add(names[type(module)])
        else:
            raise ValueError(
                f"model: cannot export a policy layer of type {type(module).__name__} (linear, tanh, relu, elu with alpha 1 only)"
            )
    if len(activations) > 1:
        raise ValueError(f"model: mixed activations {sorted(activations)} are not supported")
    extractor = policy.features_extractor if algo == "ppo" else policy.actor.features_extractor
    if type(extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"model: cannot export the features extractor {type(extractor).__name__}")
    arrays: dict[str, np.ndarray] = {}
    for k, (W, b) in enumerate(layers):
        arrays[f"W{k}"], arrays[f"b{k}"] = W, b
    space = model.action_space
    arrays["low"] = np.asarray(space.low, dtype=np.float64)
    arrays["high"] = np.asarray(space.high, dtype=np.float64)
    clip_obs = 0.0
    vn_file = folder / "vecnormalize.pkl"
    if vn_file.exists():
        vn = load_vecnormalize(vn_file)
        if vn.norm_obs:
            arrays["obs_mean"] = np.asarray(vn.obs_rms.mean, dtype=np.float64)
            arrays["obs_scale"] = np.sqrt(np.asarray(vn.obs_rms.var, dtype=np.float64) + vn.epsilon)
            clip_obs = float(vn.clip_obs)
    import stable_baselines3

    meta = {
        "format": FORMAT_VERSION,
        "algo": algo,
        "layers": len(layers),
        "activation": activations.pop() if activations else "tanh",
        "squash": bool(policy.squash_output) if algo == "ppo" else True,
        "clip_obs": clip_obs,
        "sources": sources,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
    }
    arrays["meta"] = np.array(json.dumps(meta))
    import io

    from flatbody_env.output import atomic_write

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return atomic_write(folder / POLICY_FILE, buf.getvalue())  # the one writing door (no fixed temporary name)


def load_policy(path: str | Path | None = None) -> NumpyPolicy:
    """The exported policy of the model at ``path`` (default: the shipped agent).

    Raises :class:`StalePolicyError` (a ValueError) when ``policy.npz`` is missing, of another
    :data:`FORMAT_VERSION`, or was exported from a ``model.zip`` / ``vecnormalize.pkl`` other than
    the ones beside it now; the message names the command that re-exports it.
    """
    folder = model_folder(path)
    file = folder / POLICY_FILE
    redo = f"run: flatbody export-policy {folder}"
    if not file.exists():
        raise StalePolicyError(f"policy: no {POLICY_FILE} beside {folder / 'model.zip'}; {redo}")
    from flatbody_env.physics import validation

    try:  # the one reading door: every member's declared shape and dtype checked before it is read
        arrays = validation.read_npz("policy", file, max_bytes=MAX_POLICY_BYTES, max_array_bytes=MAX_POLICY_BYTES)
    except ValueError as exc:  # not a regular file, truncated, pickled arrays, a lying header, too large
        raise DamagedPolicyError(f"{exc}; {redo}") from None
    try:
        meta = json.loads(str(arrays.pop("meta")))
        if not isinstance(meta, dict):
            raise ValueError("meta is not an object")
    except Exception as exc:  # noqa: BLE001 - no meta, bad JSON: an error, never a fall-back
        raise DamagedPolicyError(
            f"policy: {file} is damaged ({type(exc).__name__}: {' '.join(str(exc).split())[:120]}); {redo}"
        ) from None
    if meta.get("format") != FORMAT_VERSION:
        raise StalePolicyError(
            f"policy: {file} has format {meta.get('format')!r}, this version reads {FORMAT_VERSION}; {redo}"
        )
    now = _sources(folder)
    if meta.get("sources") != now:
        changed = [k for k in now if (meta.get("sources") or {}).get(k) != now[k]]
        raise StalePolicyError(f"policy: {file} is stale ({', '.join(changed)} changed since the export); {redo}")
    try:
        return _policy_from(arrays, meta)
    except (KeyError, TypeError, ValueError) as exc:
        raise DamagedPolicyError(
            f"policy: {file} is damaged ({type(exc).__name__}: {' '.join(str(exc).split())[:120]}); {redo}"
        ) from None


def _policy_from(arrays: dict, meta: dict) -> NumpyPolicy:
    """The policy of a loaded ``policy.npz``, its arrays checked (float, finite, chained shapes)."""
    from flatbody_env.physics import validation

    n = int(meta["layers"])
    if not 1 <= n <= 64:
        raise ValueError(f"layers = {n}")
    for k, v in arrays.items():
        if v.dtype.kind not in "fiu" or not np.all(np.isfinite(v)):
            raise ValueError(f"array {k} is not finite numbers")
    width = None
    for k in range(n):
        W, b = arrays[f"W{k}"], arrays[f"b{k}"]
        if W.ndim != 2 or b.shape != (W.shape[0],) or (width is not None and W.shape[1] != width):
            raise ValueError(f"layer {k} has shapes {W.shape}, {b.shape}")
        width = W.shape[0]
    if arrays["low"].shape != (width,) or arrays["high"].shape != (width,):
        raise ValueError("action bounds do not match the last layer")
    has_norm = "obs_mean" in arrays
    if has_norm and (
        arrays["obs_mean"].shape != (arrays["W0"].shape[1],)
        or arrays["obs_scale"].shape != arrays["obs_mean"].shape
        or np.any(arrays["obs_scale"] <= 0)
    ):
        raise ValueError("normalisation statistics do not match the first layer")
    return NumpyPolicy(
        weights=tuple(arrays[f"W{k}"].astype(np.float64) for k in range(n)),
        biases=tuple(arrays[f"b{k}"].astype(np.float64) for k in range(n)),
        activation=validation.string("activation", meta["activation"], choices=ACTIVATIONS),
        obs_mean=arrays["obs_mean"] if has_norm else None,
        obs_scale=arrays["obs_scale"] if has_norm else None,
        clip_obs=float(meta["clip_obs"]),
        squash=bool(meta["squash"]),
        low=arrays["low"],
        high=arrays["high"],
        meta=meta,
    )


__all__ = [
    "DamagedPolicyError",
    "MAX_MODEL_BYTES",
    "MAX_POLICY_BYTES",
    "MODEL_FORMATS",
    "model_format_of",
    "check_trusted",
    "load_replay_buffer",
    "load_torch_state",
    "load_vecnormalize",
    "read_pickled",
    "trust_policy",
    "trust_refusal",
    "load_sb3",
    "read_run_config",
    "remember_run",
    "require_trust",
    "trusted",
    "trusted_roots",
    "FORMAT_VERSION",
    "NumpyPolicy",
    "POLICY_FILE",
    "StalePolicyError",
    "export_policy",
    "load_policy",
    "model_folder",
    "sha256",
]
