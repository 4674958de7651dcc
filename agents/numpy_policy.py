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

import numpy as np

FORMAT_VERSION = 1
"""Version of the ``policy.npz`` layout; a file of another version is refused (re-export it)."""
POLICY_FILE = "policy.npz"
ACTIVATIONS = ("tanh", "relu")


class StalePolicyError(ValueError):
    """``policy.npz`` is missing, of another format version, or was exported from other files."""


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
        from agents.evaluate import shipped_model_dir

        return shipped_model_dir()
    p = Path(path)
    folder = p if p.is_dir() else p.parent
    if p.is_file() and p.name != "model.zip":
        raise ValueError(f"model: the exported policy is read beside a file named model.zip, got {str(p)!r}")
    if not (folder / "model.zip").exists():
        raise ValueError(f"model: no model at {str(p)!r} (expected a run folder with model.zip, or a model.zip)")
    return folder


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

    import torch
    import yaml
    from stable_baselines3 import PPO, SAC

    torch.set_num_threads(1)
    folder = model_folder(path)
    cfg_file = folder / "config.yml"
    config = yaml.safe_load(cfg_file.read_text(encoding="utf-8")) if cfg_file.exists() else {}
    algo = (config or {}).get("algo") or "ppo"
    if algo not in ("ppo", "sac"):
        raise ValueError(f"algo: export supports ppo and sac, got {algo!r}")
    sources = _sources(folder)
    model = {"ppo": PPO, "sac": SAC}[algo].load(str(folder / "model.zip"), device="cpu")
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
            layers.append((module.weight.detach().double().numpy().copy(), module.bias.detach().double().numpy().copy()))
        elif type(module) in names:
            activations.add(names[type(module)])
        else:
            raise ValueError(f"model: cannot export a policy layer of type {type(module).__name__} (linear, tanh, relu only)")
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
    with np.load(file, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    if meta.get("format") != FORMAT_VERSION:
        raise StalePolicyError(f"policy: {file} has format {meta.get('format')!r}, this version reads {FORMAT_VERSION}; {redo}")
    now = _sources(folder)
    if meta.get("sources") != now:
        changed = [k for k in now if (meta.get("sources") or {}).get(k) != now[k]]
        raise StalePolicyError(f"policy: {file} is stale ({', '.join(changed)} changed since the export); {redo}")
    n = int(meta["layers"])
    has_norm = "obs_mean" in arrays
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


__all__ = ["FORMAT_VERSION", "NumpyPolicy", "POLICY_FILE", "StalePolicyError", "export_policy", "load_policy", "model_folder", "sha256"]
