"""A read-only install (system site-packages, a read-only image) runs the compiled paths.

The package is copied to a folder made read-only, with a read-only home and no
``NUMBA_CACHE_DIR``; a subprocess imports it from there and runs a compiled method. As root,
permission bits do not stop writes, so the subprocess also refuses (via ``sitecustomize``) every
temporary file under the read-only folders — the probe numba itself uses to pick a cache folder.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import flatbody_env

SITECUSTOMIZE = textwrap.dedent(
    """
    import os, tempfile
    _RO = tuple(p for p in os.environ["FLATBODY_TEST_READONLY"].split(os.pathsep) if p)
    _orig = tempfile.TemporaryFile

    def _refuse(*args, dir=None, **kwargs):
        if dir is not None and os.path.abspath(str(dir)).startswith(_RO):
            raise PermissionError(13, "Permission denied (read-only test install)", str(dir))
        return _orig(*args, dir=dir, **kwargs)

    tempfile.TemporaryFile = _refuse
    """
)

PROGRAM = textwrap.dedent(
    """
    import json
    import flatbody_env, flatbody_env.integrators.jit as jit
    from flatbody_env import simulate
    run = simulate("default", t_end=0.2, method="RK4", step=0.01, times=[0.1, 0.2])
    print(json.dumps({"file": flatbody_env.__file__, "cache": jit.CACHE, "rows": run.t.tolist(),
                      "lam": run.state["lambda"].tolist()}))
    """
)


def _make_readonly(root: Path) -> None:
    for path in sorted(root.rglob("*"), reverse=True):
        mode = path.stat().st_mode
        path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    root.chmod(root.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


@pytest.mark.slow  # long: copies the package and compiles its kernels afresh
def test_compiled_method_runs_from_a_readonly_copy(tmp_path):
    src = Path(flatbody_env.__file__).resolve().parent
    site = tmp_path / "site"
    shutil.copytree(src, site / "flatbody_env", ignore=shutil.ignore_patterns("__pycache__"))
    home = tmp_path / "home"
    home.mkdir()
    hooks = tmp_path / "hooks"
    hooks.mkdir()
    (hooks / "sitecustomize.py").write_text(SITECUSTOMIZE)
    _make_readonly(site)
    _make_readonly(home)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHON"))}
    env.update(
        HOME=str(home),
        XDG_CACHE_HOME=str(home / ".cache"),
        PYTHONPATH=os.pathsep.join([str(hooks), str(site)]),
        PYTHONDONTWRITEBYTECODE="1",
        FLATBODY_TEST_READONLY=os.pathsep.join([str(site), str(home)]),
    )
    try:
        proc = subprocess.run(
            [sys.executable, "-c", PROGRAM], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300
        )
    finally:
        for path in [site, home, *site.rglob("*")]:
            path.chmod(path.stat().st_mode | stat.S_IWUSR)
    assert proc.returncode == 0, proc.stderr[-2000:]
    import json

    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["file"].startswith(str(site))  # the read-only copy ran, not the checkout
    assert out["cache"] is False  # nowhere to write: compiled in memory
    assert out["rows"] == [0.1, 0.2]
    # nothing was written into the read-only copy
    assert not any(p.name == "__pycache__" for p in site.rglob("*"))
    # same numbers as the writable install
    from flatbody_env import simulate

    ref = simulate("default", t_end=0.2, method="RK4", step=0.01, times=[0.1, 0.2])
    assert out["lam"] == ref.state["lambda"].tolist()
