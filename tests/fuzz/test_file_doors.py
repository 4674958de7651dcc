"""The one reading door (``flatbody_env.physics.validation``: ``read_bytes`` and the readers built on it): a FIFO, a
device, a file over the size cap, a YAML alias bomb or an npz whose headers declare huge arrays is refused naming the
field — never a hang, never a read into memory of what the file claims."""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from flatbody_env.physics import validation

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


def test_short_never_builds_the_whole_repr():
    """validation._short cuts before formatting: an alias bomb's shared lists (9**9 items once expanded) print at once."""
    inner: list = ["lol"] * 9
    for _ in range(8):
        inner = [inner] * 9
    text = validation._short(inner)
    assert len(text) <= 60 and text.startswith("[[[")
    with pytest.raises(ValueError, match=r"^config\.yml\.algo: must be a string, got \[\[\["):
        validation.string("config.yml.algo", inner)
