"""Every file the program reads goes through one guarded door (``flatbody_env.physics.validation``: ``read_bytes``
and the readers built on it): a FIFO, a device, a file over the door's size cap, a YAML alias bomb or an npz whose
headers declare huge arrays is refused with one line naming the field (exit 2) — never a hang, never a read into
memory of what the file claims. Each door is exercised through the command that reads it, in-process under a time
limit (``hostile.run_case``: a hang is an outcome, not a stuck test)."""

from __future__ import annotations

import io
import os
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import hostile  # noqa: E402

from agents.evaluate import MODELS_DIR  # noqa: E402
from agents.numpy_policy import MAX_MODEL_BYTES, MAX_POLICY_BYTES  # noqa: E402
from flatbody_env.physics import validation  # noqa: E402

V0_AGENT = MODELS_DIR / "ppo-FlatBody-v0"
"""A shipped SB3 agent with VecNormalize statistics (its pickles are the doors fuzzed here)."""

LIMIT_S = 60.0
ALIAS_BOMB = "".join(  # 9 levels of 9 aliases each: 9**9 (387 million) strings once expanded, in a few hundred bytes
    f"{k}: &{k} [{', '.join([f'*{p}'] * 9) if p else ', '.join(['lol'] * 9)}]\n"
    for p, k in zip(["", *"abcdefgh"], "abcdefghi")
)


def _lying_npz(path: Path) -> None:
    """A small npz (a few MB) whose member declares a 30 000 x 30 000 float64 array (6.7 GiB) it does not hold."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (30_000, 30_000)})
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("W0.npy", header.getvalue() + bytes(3_000_000))
        z.writestr("meta.npy", header.getvalue())


def _plant(path: Path, kind: str, cap: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists() or path.is_symlink():
        path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev-zero":
        os.symlink("/dev/zero", path)
    elif kind == "oversize":
        with open(path, "wb") as fh:  # sparse: the size the door sees, no disk used
            fh.truncate(cap + 1)
    elif kind == "alias-bomb":
        path.write_text(ALIAS_BOMB)
    elif kind == "lying-npz":
        _lying_npz(path)
    else:
        raise AssertionError(kind)


def _model_copy(tmp: Path) -> Path:
    d = tmp / "model"
    d.mkdir()
    for f in ("model.zip", "config.yml", "vecnormalize.pkl", "policy.npz"):
        shutil.copy(V0_AGENT / f, d / f)
    return d


def _resume_folder(tmp: Path) -> Path:
    d = tmp / "run"
    (d / "checkpoints").mkdir(parents=True)
    shutil.copy(V0_AGENT / "config.yml", d / "config.yml")
    (d / "checkpoints" / "rl_model_128_steps.zip").write_bytes(b"a checkpoint")
    return d


def _plans_file(tmp: Path) -> Path:
    return tmp / "plans.npz"


# door: (where the hostile file goes, its cap, argv, runner, the field named, the kinds that apply)
YAML = ("fifo", "dev-zero", "oversize", "alias-bomb")
NPZ = ("fifo", "dev-zero", "oversize", "lying-npz")
PLAIN = ("fifo", "dev-zero", "oversize")
DOORS = {
    "evaluate --docs": (
        lambda t: t / "page.md",
        validation.MAX_TEXT_BYTES,
        lambda t, f: ["evaluate", "--docs", str(f)],
        "flatbody",
        "docs",
        PLAIN,
    ),
    "chart --tasks --from": (
        lambda t: t / "reports" / "FlatBody-v0.json",
        validation.MAX_JSON_BYTES,
        lambda t, f: ["chart", "--tasks", "--from", str(f.parent), "--out", str(t)],
        "flatbody",
        "--from",
        PLAIN,
    ),
    "train --hyperparams-file": (
        lambda t: t / "hp.yml",
        validation.MAX_YAML_BYTES,
        lambda t, f: ["train", "--algo", "ppo", "--hyperparams-file", str(f), "--out", str(t / "o"), "--no-progress"],
        "flatbody",
        "hyperparams_file",
        YAML,
    ),
    "tune --search-file": (
        lambda t: t / "search.yml",
        validation.MAX_YAML_BYTES,
        lambda t, f: ["tune", "--algo", "ppo", "--search-file", str(f), "--storage", f"sqlite:///{t}/o.db"],
        "flatbody",
        "search_file",
        YAML,
    ),
    "train --resume config.yml": (
        lambda t: _resume_folder(t) / "config.yml",
        validation.MAX_YAML_BYTES,
        lambda t, f: ["train", "--algo", "ppo", "--resume", "--trust", "--out", str(f.parent), "--no-progress"],
        "flatbody",
        "config.yml",
        YAML,
    ),
    "train --resume run.json": (
        lambda t: _resume_folder(t) / "run.json",
        validation.MAX_JSON_BYTES,
        lambda t, f: ["train", "--algo", "ppo", "--resume", "--trust", "--out", str(f.parent), "--no-progress"],
        "flatbody",
        "run.json",
        PLAIN,
    ),
    "evaluate config.yml": (
        lambda t: _model_copy(t) / "config.yml",
        validation.MAX_YAML_BYTES,
        lambda t, f: ["evaluate", str(f.parent), "--episodes", "1", "--no-baselines"],
        "flatbody",
        "config.yml",
        YAML,
    ),
    "record --agent config.yml": (
        lambda t: _model_copy(t) / "config.yml",
        validation.MAX_YAML_BYTES,
        lambda t, f: ["record", "--agent", str(f.parent), "--out", str(t / "a.rrd")],
        "flatbody",
        "config.yml",
        YAML,
    ),
    "evaluate policy.npz": (
        lambda t: _model_copy(t) / "policy.npz",
        MAX_POLICY_BYTES,
        lambda t, f: ["evaluate", str(f.parent), "--episodes", "1", "--no-baselines"],
        "flatbody",
        "policy",
        NPZ,
    ),
    "evaluate vecnormalize.pkl": (
        lambda t: _model_copy(t) / "vecnormalize.pkl",
        MAX_MODEL_BYTES,
        lambda t, f: ["evaluate", str(f.parent), "--trust", "--backend", "sb3", "--episodes", "1", "--no-baselines"],
        "flatbody",
        "model",
        PLAIN,
    ),
    "evaluate model.zip": (
        lambda t: _model_copy(t) / "model.zip",
        MAX_MODEL_BYTES,
        lambda t, f: ["evaluate", str(f.parent), "--episodes", "1", "--no-baselines"],
        "flatbody",
        "model",
        PLAIN,
    ),
    "bench service --plot-only": (
        lambda t: t / "service_benchmark.json",
        validation.MAX_JSON_BYTES,
        lambda t, f: ["bench", "service", "--plot-only", "--out-dir", str(t)],
        "flatbody",
        "--plot-only",
        PLAIN,
    ),
    "chart --plot-only": (
        lambda t: t / "work_precision.csv",
        validation.MAX_JSON_BYTES,
        lambda t, f: ["chart", "--plot-only", "--out", str(t)],
        "flatbody",
        "csv",
        PLAIN,
    ),
    "imitate clone --plans": (
        _plans_file,
        validation.MAX_JSON_BYTES,
        lambda t, f: [
            "imitate",
            "clone",
            "--plans",
            str(f),
            "--model",
            str(V0_AGENT),
            "--out",
            str(t / "bc"),
        ],
        "flatbody",
        "plans",
        NPZ,
    ),
}
CASES = [(door, kind) for door, spec in DOORS.items() for kind in spec[5]]


@pytest.mark.parametrize("door, kind", CASES, ids=[f"{d}-{k}" for d, k in CASES])
def test_every_door_refuses_hostile_files_in_one_line(tmp_path, monkeypatch, door, kind):
    monkeypatch.setenv("FLATBODY_CONFIG_HOME", str(tmp_path / "config"))
    place, cap, argv_of, runner, field, _ = DOORS[door]
    work = tmp_path / "work"
    work.mkdir()
    path = place(work)
    _plant(path, kind, cap)
    argv = argv_of(work, path)
    assert runner == "flatbody"
    row = hostile.run_case(argv, limit=LIMIT_S)
    assert row["outcome"] == "exit" and row["code"] == 2 and row["err_lines"] == 1, row
    assert f"{field}" in row["err"], row


@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "oversize", "alias-bomb"])
def test_the_readers_refuse_before_reading(tmp_path, kind):
    """The door's functions themselves: each refuses naming the field (and, for the sizes, before reading)."""
    path = tmp_path / "f.yml"
    _plant(path, kind, validation.MAX_YAML_BYTES)
    with pytest.raises(ValueError, match=r"^field"):
        validation.read_yaml("field", path)


def test_read_npz_checks_the_declared_sizes_before_reading(tmp_path):
    _lying_npz(tmp_path / "x.npz")
    with pytest.raises(ValueError, match=r"^policy: .*declares 6\.7\d* GiB of float64 \(30000, 30000\)"):
        validation.read_npz("policy", tmp_path / "x.npz")
    np.savez_compressed(tmp_path / "ok.npz", a=np.arange(6.0).reshape(2, 3), s=np.array("text"))
    arrays = validation.read_npz("policy", tmp_path / "ok.npz")
    assert arrays["a"].shape == (2, 3) and str(arrays["s"]) == "text"
    big = np.zeros(1000)  # honest but over the budget given
    np.savez_compressed(tmp_path / "big.npz", a=big)
    with pytest.raises(ValueError, match="declare more than"):
        validation.read_npz("policy", tmp_path / "big.npz", max_array_bytes=4000)
    np.save(tmp_path / "obj.npy", np.array([{"x": 1}], dtype=object))
    with zipfile.ZipFile(tmp_path / "obj.npz", "w") as z:
        z.write(tmp_path / "obj.npy", "obj.npy")
    with pytest.raises(ValueError, match="Python objects"):
        validation.read_npz("policy", tmp_path / "obj.npz")


def test_yaml_aliases_within_the_budget_still_load():
    assert validation.parse_yaml("x", "a: &a [1, 2]\nb: *a\nc: {<<: {k: 1}}\n") == {
        "a": [1, 2],
        "b": [1, 2],
        "c": {"k": 1},
    }
    with pytest.raises(ValueError, match="recursive"):
        validation.parse_yaml("x", "a: &a [1, *a]\n")
    with pytest.raises(ValueError, match="nodes"):
        validation.parse_yaml("x", "a: &a [1, 2, 3]\nb: [*a, *a, *a]\n", max_nodes=10)


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (10**99, "1e+99"),
        (-(10**30) - 7, "-1e+30"),
        (10**400, "an integer of about 400 digits"),
        (-(10**400), "a negative integer of about 400 digits"),
    ],
)
def test_a_huge_integer_is_shown_by_its_size(value, shown):
    """A huge integer (a YAML value, ``--budget ppo=1e99``) is shown as 1e+99, never as 60 of its digits cut off."""
    with pytest.raises(ValueError) as refused:
        validation.integer("n", value, low=0, high=10)
    assert str(refused.value).endswith(f"got {shown}")


def test_short_never_builds_the_whole_repr():
    """validation.shown cuts before formatting: an alias bomb's shared lists (9**9 items once expanded) print at once."""
    inner: list = ["lol"] * 9
    for _ in range(8):
        inner = [inner] * 9
    text = validation.shown(inner)
    assert len(text) <= 60 and text.startswith("[[[")
    with pytest.raises(ValueError, match=r"^config\.yml\.algo: must be a string, got \[\[\["):
        validation.string("config.yml.algo", inner)
