"""Progress of long work when stderr is not a terminal: plain periodic lines on stderr, none on stdout."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from flatbody_env import progress

ROOT = Path(__file__).resolve().parents[2]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "FLATBODY_PROGRESS_S"}
    env.update(PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", **extra)
    return env


def _run(args: list[str], **extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=ROOT, env=_env(**extra), capture_output=True, text=True, timeout=300)


def test_piped_progress_prints_periodic_lines_on_stderr():
    code = (
        "import time\n"
        "from flatbody_env.progress import progress_bar\n"
        "t0 = time.monotonic()\n"
        "bar = progress_bar(total=20, desc='work', unit='task')\n"
        "for i in range(20):\n"
        "    time.sleep(0.02)\n"
        "    bar.set_postfix_str(f'item {i}')\n"
        "    bar.update(1)\n"
        "bar.close()\n"
        "print(type(bar).__name__, time.monotonic() - t0)\n"
    )
    r = _run([sys.executable, "-c", code], FLATBODY_PROGRESS_S="0.1")
    assert r.returncode == 0, r.stderr
    name, seconds = r.stdout.split()  # stdout stays the command's
    assert name == "LineProgress" and r.stdout.count("\n") == 1, r.stdout
    lines = r.stderr.splitlines()
    # the work takes at least 20 x 0.02 s: lines every 0.1 s, at most one per interval it took, and the last one
    assert "\r" not in r.stderr and 2 <= len(lines) <= float(seconds) / 0.1 + 1, (seconds, r.stderr)
    assert all(line.startswith("work: ") and " tasks (" in line for line in lines)
    assert "[item " in lines[0] and "left" in lines[0]
    assert lines[-1].startswith("work: 20/20 tasks (100%)") and lines[-1].endswith("- done")


def test_short_piped_work_prints_nothing_and_long_work_is_reported(tmp_path, monkeypatch):
    argv = [
        sys.executable,
        "-m",
        "flatbody_env.cli",
        "sweep",
        "stability-map",
        "--grid",
        "8",
        "--chunk",
        "2",
        "--workers",
        "0",
    ]
    # work shorter than the interval prints no progress line (an interval of an hour: on a busy machine this
    # sweep can outlast the default 10 s, which FLATBODY_PROGRESS_S unset gives, as checked at the end)
    quiet = _run([*argv, "--out", str(tmp_path / "a")], FLATBODY_PROGRESS_S="3600")
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stderr == ""
    loud = _run([*argv, "--out", str(tmp_path / "b")], FLATBODY_PROGRESS_S="0")
    assert loud.returncode == 0, loud.stderr
    lines = loud.stderr.splitlines()
    assert lines[0].startswith("sweep stability-map: 1/4 tasks (25%)"), loud.stderr
    assert lines[-1].startswith("sweep stability-map: 4/4 tasks (100%)") and lines[-1].endswith("- done")
    # the report itself is unchanged (its last line names the files written, each run in its own folder)
    assert loud.stdout.replace(str(tmp_path / "b"), "OUT") == quiet.stdout.replace(str(tmp_path / "a"), "OUT")
    assert (
        quiet.stdout.splitlines()[-1]
        == f"wrote {tmp_path / 'a' / 'results.sqlite'}, {tmp_path / 'a' / 'stability_map.csv'}"
    )
    nobar = _run([*argv, "--out", str(tmp_path / "c"), "--no-progress"], FLATBODY_PROGRESS_S="0")
    assert nobar.returncode == 0 and nobar.stderr == ""
    monkeypatch.delenv("FLATBODY_PROGRESS_S", raising=False)
    assert progress.interval_s() == progress.INTERVAL_S == 10.0


def test_a_bad_interval_is_one_line(tmp_path):
    r = _run(
        [
            sys.executable,
            "-m",
            "flatbody_env.cli",
            "sweep",
            "stability-map",
            "--grid",
            "4",
            "--workers",
            "0",
            "--out",
            str(tmp_path),
        ],
        FLATBODY_PROGRESS_S="soon",
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "FLATBODY_PROGRESS_S" in r.stderr


@pytest.mark.parametrize("interval", [None, "0"])
def test_line_progress_counts_from_a_resumed_start(interval, monkeypatch):
    import io

    from flatbody_env.progress import LineProgress

    if interval is not None:
        monkeypatch.setenv("FLATBODY_PROGRESS_S", interval)
    else:
        monkeypatch.delenv("FLATBODY_PROGRESS_S", raising=False)
    out = io.StringIO()
    bar = LineProgress(total=10, initial=4, desc="train", unit="step", file=out)
    for _ in range(6):
        bar.update(1)
    bar.close()
    text = out.getvalue()
    if interval is None:
        assert text == ""  # under the 10 s default
    else:
        assert text.splitlines()[0].startswith("train: 5/10 steps (50%)") and text.splitlines()[-1].endswith("- done")


def test_iterating_a_line_progress_ends_it():
    import io

    from flatbody_env.progress import LineProgress

    out = io.StringIO()
    assert list(LineProgress(range(5), desc="rows", unit="row", file=out, interval=0)) == [0, 1, 2, 3, 4]
    lines = out.getvalue().splitlines()
    assert len(lines) == 6 and lines[-1].startswith("rows: 5/5 rows (100%)") and lines[-1].endswith("- done")
