"""The recorder's file sink (flatbody_env.recording.sink): rerun's stream copied to the file by our thread,
renamed into place at close; a failed write is one line, never a hang; nothing left behind."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np
import pytest

from flatbody_env.output import OutputError
from flatbody_env.recording.reader import read_recording, verify_recording
from flatbody_env.recording.writer import Recorder
from flatbody_env.scene import load_scene
from flatbody_env.simulation import simulate

ENV = {**os.environ, "PYTHONWARNINGS": "ignore"}


@pytest.fixture(scope="module")
def run():
    scene = load_scene("default")
    return scene, simulate(scene, t_end=2.0, times=np.linspace(0.0, 2.0, 50), with_rotation=True)


def test_a_closed_recording_is_renamed_into_place_and_leaves_nothing_behind(run, tmp_path, monkeypatch):
    scene, traj = run
    pipes = tmp_path / "tmp"
    pipes.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(pipes))  # where the sink makes its FIFO
    out = tmp_path / "out"
    out.mkdir()
    path = out / "run.rrd"
    path.write_bytes(b"old")
    with Recorder(path, scene.body, block=8) as rec:
        for k in range(traj.t.size):
            rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
        assert path.read_bytes() == b"old"  # replaced in one step, at close
    assert "verified" in verify_recording(path)
    assert read_recording(path)["/world/body"].step.size == traj.t.size
    assert sorted(p.name for p in out.iterdir()) == ["run.rrd"]
    assert list(pipes.iterdir()) == []  # the FIFO's folder is removed


def test_a_failed_write_is_an_output_error_at_the_next_block(run, tmp_path):
    """The copy thread's OSError is raised in the recording's thread at the next block (a long episode stops
    early), names the file, and the temporary file is removed; closing again says the same."""
    scene, traj = run
    path = tmp_path / "run.rrd"
    rec = Recorder(path, scene.body, block=4)
    for k in range(8):
        rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
    sink = rec._sink
    assert sink is not None
    sink.error = OSError(28, "No space left on device")  # as the copy thread records a failed write
    with pytest.raises(OutputError, match=r"cannot write '.*run\.rrd': no space left on device"):
        for k in range(8, 12):
            rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
    with pytest.raises(OutputError, match="no space left"):
        rec.close()
    assert list(tmp_path.iterdir()) == []


def test_a_recording_never_closed_leaves_no_file_and_the_program_exits(tmp_path):
    path = tmp_path / "run.rrd"
    code = (
        "import numpy as np; from flatbody_env.scene import load_scene; from flatbody_env.simulation import simulate; "
        "from flatbody_env.recording.writer import Recorder; s = load_scene('default'); "
        "tr = simulate(s, t_end=1.0, times=np.linspace(0, 1, 300), with_rotation=True); "
        f"rec = Recorder({str(path)!r}, s.body, block=16)\n"
        "for k in range(300): rec.append(tr.t[k], tr.y[:, k], tr.rotation[k], energy=tr.energy[k])\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=ENV, check=False
    )  # hang guard
    assert r.returncode == 0, r.stderr[-2000:]
    assert list(tmp_path.iterdir()) == []


def test_record_env_on_a_disk_that_fills_is_one_line(tmp_path):
    """``record-env`` streams its episode: the file-size limit reached mid-episode is one line, exit 1."""
    target = tmp_path / "ep.rrd"
    code = (
        "import resource, sys; from flatbody_env.cli import record; record.check_space = lambda *a, **k: None; "
        "resource.setrlimit(resource.RLIMIT_FSIZE, (200000, 200000)); from flatbody_env.cli.main import main; "
        f"sys.exit(main(['record-env', '--max-steps', '3000', '--out', {str(target)!r}]))"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=ENV, check=False
    )  # hang guard
    assert r.returncode == 1, r.stderr[-2000:]
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert str(target) in lines[0] and "file-size limit" in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


def test_without_fifos_the_stream_is_written_at_close(run, tmp_path, monkeypatch):
    """Where ``os.mkfifo`` does not exist, rerun's binary stream is read once at close: the same verified file."""
    scene, traj = run
    monkeypatch.delattr(os, "mkfifo")
    path = tmp_path / "run.rrd"
    with Recorder(path, scene.body, block=8) as rec:
        for k in range(traj.t.size):
            rec.append(traj.t[k], traj.y[:, k], traj.rotation[k], energy=traj.energy[k])
        assert not path.exists()
    assert "verified" in verify_recording(path)
    assert read_recording(path)["/world/body"].step.size == traj.t.size
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.rrd"]
