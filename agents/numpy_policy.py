"""A trained agent's deterministic policy as plain numpy: no torch, no Stable-Baselines3 at run time.

``flatbody export-policy [MODEL]`` (:func:`export_policy`) reads the SB3 model (``model.zip``) and
its VecNormalize statistics (``vecnormalize.pkl``) once, with torch, and writes
``policy.npz`` beside them. :class:`NumpyPolicy` evaluates it with numpy alone; ``flatbody demo``
and ``flatbody evaluate`` use it (:class:`agents.evaluate.Agent`), so they never import torch.

What is exported (the deterministic action SB3's ``predict(obs, deterministic=True)`` returns):

* the observation normalisation of VecNormalize: clip((o − mean)/√(var + ε), −clip, clip)
  (when the run normalised observations);
* the actor's MLP (``mlp_extractor.policy_net`` of an actor-critic policy, ``actor.latent_pi``
  of SAC), as (W, b) per linear layer and the activation between them (tanh or ReLU);
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

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

FORMAT_VERSION = 1
"""Version of the ``policy.npz`` layout; a file of another version is refused (re-export it)."""
POLICY_FILE = "policy.npz"
ACTIVATIONS = ("tanh", "relu")
MODELS_DIR = Path(__file__).resolve().parent / "models"
"""Where shipped agents live: ``MODELS_DIR/<algo>-<env id>/`` (model.zip, config.yml, ...); also :data:`agents.evaluate.MODELS_DIR`."""


def shipped_model_dir() -> Path:
    """The folder of the agent shipped in the package (``agents/models/ppo-FlatBody-v0``); also :func:`agents.evaluate.shipped_model_dir`."""
    return MODELS_DIR / "ppo-FlatBody-v0"


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


def _trust_file() -> Path:
    import os

    base = os.environ.get("FLATBODY_CONFIG_HOME") or os.path.join(
        os.environ.get("XDG_CONFIG_HOME") or os.path.expanduser("~/.config"), "flatbody"
    )
    return Path(base) / "trusted-runs.txt"


def trusted_roots() -> list[Path]:
    """Folders whose pickles load without ``--trust``: the shipped agents (``agents/models``), the run
    folders this user created with ``flatbody train`` / ``flatbody sweep`` (:func:`remember_run`) and
    the folders listed in ``$FLATBODY_TRUSTED_DIRS`` (``os.pathsep``-separated)."""
    import os

    roots = [MODELS_DIR.resolve()]
    roots += [
        Path(x).expanduser().resolve()
        for x in os.environ.get("FLATBODY_TRUSTED_DIRS", "").split(os.pathsep)
        if x.strip()
    ]
    try:
        text = _trust_file().read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        text = ""
    roots += [Path(line) for line in text.splitlines() if line.strip()]
    return roots


def trusted(folder: str | Path) -> bool:
    """Whether ``folder`` lies in one of :func:`trusted_roots`."""
    f = Path(folder).resolve()
    return any(f == r or r in f.parents for r in trusted_roots())


def remember_run(folder: str | Path) -> None:
    """Record ``folder`` as one of this user's run folders (best effort: an unwritable config is ignored)."""
    f = Path(folder).resolve()
    try:
        if trusted(f):
            return
        path = _trust_file()
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a", encoding="utf-8") as fh:
            fh.write(f"{f}\n")
    except OSError:
        pass


def check_trusted(folder: str | Path, what: str) -> None:
    """Refuse (``ValueError`` naming ``model``) to unpickle ``what`` from an untrusted folder while
    :func:`require_trust` is on."""
    if _TRUST["required"] and not trusted(folder):
        raise ValueError(
            f"model: loading {what} from {str(folder)[:80]!r} unpickles it, which can run arbitrary code, and the folder is "
            "neither the shipped agent nor one of your runs (flatbody train, sweep); pass --trust if you trust its source "
            "(docs/reliability.md, Trust model)"
        )


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with Path(path).open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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
    import yaml

    cfg_file = Path(folder) / "config.yml"
    if not cfg_file.exists():
        return {}
    try:
        if not cfg_file.is_file() or cfg_file.stat().st_size > 1 << 20:
            raise ValueError("not a regular file of at most 1 MiB")
        config = yaml.safe_load(cfg_file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, yaml.YAMLError) as exc:
        raise ValueError(
            f"config.yml: cannot read {str(cfg_file)[:80]!r} ({' '.join(str(exc).split())[:120]})"
        ) from None
    if config is None:
        return {}
    if not isinstance(config, dict):
        raise ValueError(
            f"config.yml: {str(cfg_file)[:80]!r} must hold a mapping (algo, env_id, hyperparams), got a {type(config).__name__}"
        )
    hp = config.get("hyperparams")
    if hp is not None and not isinstance(hp, dict):
        raise ValueError(f"config.yml.hyperparams: must be a mapping, got a {type(hp).__name__}")
    if hp and hp.get("env_kwargs") is not None and not isinstance(hp["env_kwargs"], dict):
        raise ValueError(
            f"config.yml.hyperparams.env_kwargs: must be a mapping, got a {type(hp['env_kwargs']).__name__}"
        )
    for key in ("algo", "env_id"):
        if config.get(key) is not None and not isinstance(config[key], str):
            raise ValueError(f"config.yml.{key}: must be a string, got {config[key]!r:.60}")
    return config


def load_sb3(cls, model_file: Path):
    """``cls.load(model_file)`` on the CPU; a file SB3 cannot read (empty, truncated, not a model) is a
    one-line ``ValueError`` naming ``model``."""
    try:
        if Path(model_file).stat().st_size == 0:
            raise ValueError("the file is empty")
        return cls.load(str(model_file), device="cpu")
    except Exception as exc:  # noqa: BLE001 - zipfile.BadZipFile, KeyError, pickle errors, RuntimeError of torch.load
        raise ValueError(
            f"model: cannot load {str(model_file)[:80]!r} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
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
        act = np.tanh if self.activation == "tanh" else (lambda v: np.maximum(v, 0.0))
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
    policy is not an MLP of linear layers with tanh/ReLU (the only kind this evaluator runs).
    """
    import pickle

    folder = model_folder(path)
    config = read_run_config(folder)
    algo = config.get("algo") or "ppo"
    if algo not in ("ppo", "sac"):
        raise ValueError(f"algo: export supports ppo and sac, got {algo!r}")
    check_trusted(folder, "model.zip and vecnormalize.pkl")
    import torch
    from stable_baselines3 import PPO, SAC

    torch.set_num_threads(1)
    sources = _sources(folder)
    model = load_sb3({"ppo": PPO, "sac": SAC}[algo], folder / "model.zip")
    policy = model.policy
    if algo == "sac":
        trunk, head = policy.actor.latent_pi, policy.actor.mu
    else:
        trunk, head = policy.mlp_extractor.policy_net, policy.action_net
    names = {torch.nn.Tanh: "tanh", torch.nn.ReLU: "relu"}
    layers, activations = [], set()

    def flat(module):  # nested Sequentials (SB3 builds some MLPs that way) in order
        if isinstance(module, torch.nn.Sequential):
            return [leaf for child in module for leaf in flat(child)]
        return [module]

    for module in flat(trunk) + flat(head):
        if isinstance(module, torch.nn.Linear):
            layers.append(
                (module.weight.detach().double().numpy().copy(), module.bias.detach().double().numpy().copy())
            )
        elif type(module) in names:
            activations.add(names[type(module)])
        else:
            raise ValueError(
                f"model: cannot export a policy layer of type {type(module).__name__} (linear, tanh, relu only)"
            )
    if len(activations) > 1:
        raise ValueError(f"model: mixed activations {sorted(activations)} are not supported")
    if type(policy.features_extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"model: cannot export the features extractor {type(policy.features_extractor).__name__}")
    arrays: dict[str, np.ndarray] = {}
    for k, (W, b) in enumerate(layers):
        arrays[f"W{k}"], arrays[f"b{k}"] = W, b
    space = model.action_space
    arrays["low"] = np.asarray(space.low, dtype=np.float64)
    arrays["high"] = np.asarray(space.high, dtype=np.float64)
    clip_obs = 0.0
    vn_file = folder / "vecnormalize.pkl"
    if vn_file.exists():
        with vn_file.open("rb") as fh:
            vn = pickle.load(fh)
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
        "squash": bool(policy.squash_output) if algo != "sac" else True,
        "clip_obs": clip_obs,
        "sources": sources,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
    }
    arrays["meta"] = np.array(json.dumps(meta))
    out = folder / POLICY_FILE
    tmp = out.with_suffix(".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(out)
    return out


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
    try:
        with np.load(file, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
        meta = json.loads(str(arrays.pop("meta")))
        if not isinstance(meta, dict):
            raise ValueError("meta is not an object")
    except Exception as exc:  # noqa: BLE001 - truncated, not an npz, pickled arrays, bad JSON: an error, never a fall-back
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
        weights=tuple(arrays[f"W{k}"] for k in range(n)),
        biases=tuple(arrays[f"b{k}"] for k in range(n)),
        activation=meta["activation"] if meta["activation"] in ACTIVATIONS else "tanh",
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
    "check_trusted",
    "trust_policy",
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
