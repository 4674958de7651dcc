"""``bash .ci/gpu OUTDIR``, the checks of a CUDA machine, tells the story docs/gpu.md tells ("Checking a GPU
machine"): the same commands with the same flags, each step refused or run as documented. Without a GPU the script
must stop at once with one line (never half-run a check on the CPU)."""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / ".ci" / "gpu"


def _documented_commands() -> list[list[str]]:
    text = (ROOT / "docs" / "gpu.md").read_text()
    section = text[text.index("## Checking a GPU machine") :]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1).replace("\\\n", " ")
    return [shlex.split(line.split("#", 1)[0]) for line in block.splitlines() if line.strip()]


def _script_words() -> str:
    return SCRIPT.read_text().replace("\\\n", " ")


def test_the_script_runs_every_documented_check_with_its_flags():
    script = _script_words()
    commands = _documented_commands()
    assert len(commands) == 4
    for words in commands:
        head = " ".join(words[:3]) if words[0] == "flatbody" else " ".join(words[:4])
        # the script calls the CLI as a module (the checkout need not be installed on the GPU machine)
        head = head.replace("flatbody ", "python3 -m flatbody_env.cli ").replace("python ", "python3 ")
        assert head in script, f".ci/gpu does not run the documented check {head!r}"
        flags = [w for w in words if w.startswith("-")]
        for flag in flags:
            assert flag in script, f".ci/gpu runs {head!r} without the documented {flag}"
        for word in words:
            if re.fullmatch(r"\d{5,}|\d+-\d+|\d+(,\d+)+|[A-Za-z_-]+=\d+", word):
                assert word in script, f".ci/gpu runs {head!r} with other numbers than documented ({word})"
    for path in re.findall(r"tests/\S+\.py", " ".join(" ".join(w) for w in commands)):
        assert (ROOT / path).exists(), path


def _run(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=120, cwd=ROOT, env=env)


def test_usage_and_an_unknown_step_are_one_line_and_exit_2(tmp_path):
    done = _run()
    assert done.returncode == 2 and done.stderr.strip().startswith("usage: bash .ci/gpu OUTDIR")
    done = _run(str(tmp_path / "out"), "tests", "everything")
    assert done.returncode == 2
    assert done.stderr.strip() == "step: must be one of tests, bench, train, benchmark, got 'everything'"
    assert not (tmp_path / "out").exists()  # refused before anything is written


def test_without_a_gpu_it_stops_at_once_saying_so(tmp_path):
    from numba import cuda

    if cuda.is_available():
        pytest.skip("a CUDA GPU is here: the script would run its checks")
    done = _run(str(tmp_path / "out"), "bench")
    assert done.returncode == 2
    assert "no CUDA GPU here" in done.stderr
    assert done.stderr.count("\n") == 1
    assert not (tmp_path / "out" / "summary.txt").exists()
