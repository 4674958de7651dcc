"""``RecorderProcess``: recordings written by a helper process are the files the process itself writes."""

from __future__ import annotations

import numpy as np
import pytest

from flatbody_env.recording.process import RecorderProcess
from flatbody_env.recording.reader import read_recording, verify_recording
from recording_oracles import record_flatbody_episode


def _episode(path, recorder=None) -> None:
    record_flatbody_episode(path, seed=3, steps=40, recorder=recorder)


def test_recorder_process_writes_the_file_the_process_itself_writes(tmp_path):
    _episode(tmp_path / "here.rrd")
    with RecorderProcess() as helper:
        _episode(tmp_path / "helper.rrd", recorder=helper)
        _episode(tmp_path / "again.rrd", recorder=helper)  # one helper, recording after recording
    verify_recording(tmp_path / "helper.rrd")
    here, there, again = (read_recording(tmp_path / f"{n}.rrd") for n in ("here", "helper", "again"))
    assert set(here.entities) == set(there.entities) == set(again.entities) and len(here.entities) >= 40
    for name, e in here.entities.items():
        for other in (there, again):
            o = other.entities[name]
            np.testing.assert_array_equal(o.step, e.step, err_msg=name)
            np.testing.assert_array_equal(o.sim_time, e.sim_time, err_msg=name)
            for comp, values in e.components.items():
                if isinstance(values, np.ndarray):
                    np.testing.assert_array_equal(o.components[comp], values, err_msg=f"{name} {comp}")
                else:
                    assert o.components[comp] == values, f"{name} {comp}"
    assert set(here.static) == set(there.static) and here.views == there.views


def test_recorder_process_raises_the_helpers_error_at_close(tmp_path):
    from flatbody_env.physics.state import STATE_NAMES, pack
    from flatbody_env.scene import load_scene

    scene = load_scene("default")
    body, y0 = scene.body, pack(scene.state)
    with RecorderProcess() as helper:
        rec = helper(tmp_path / "bad.rrd", body, episode=True)
        Y = np.stack([y0, y0], axis=1)
        Y[STATE_NAMES.index("lambda"), 1] = -1.0
        rec.extend([0.0, 0.1], Y, np.stack([np.eye(3)] * 2))
        with pytest.raises(ValueError, match="states: lambda must be > 0"):
            rec.close()
        with pytest.raises(ValueError, match="path: a rerun recording file must end in .rrd"):
            helper(tmp_path / "bad.txt", body).close()
        ok = helper(tmp_path / "ok.rrd", body)  # the helper goes on serving after an error
        ok.extend([0.0], y0[:, None], np.eye(3)[None])
        assert ok.close() == tmp_path / "ok.rrd"
    verify_recording(tmp_path / "ok.rrd")


def test_a_helper_that_ended_is_named_not_waited_for(tmp_path):
    from flatbody_env.physics.body import default_body

    helper = RecorderProcess()
    helper._proc.kill()
    helper._proc.wait()
    with pytest.raises(RuntimeError, match="recorder process: it ended"):
        rec = helper(tmp_path / "x.rrd", default_body())
        rec.close()
    helper.close()


def test_a_helper_only_where_it_can_help(monkeypatch):
    from flatbody_env.recording import process

    with process.helper_recorder(False) as helper:
        assert helper is None  # nothing to record
    monkeypatch.setattr(process, "can_overlap", lambda: False)
    with process.helper_recorder(True) as helper:
        assert helper is None  # one processor: recording in the process itself is faster
    monkeypatch.setattr(process, "can_overlap", lambda: True)
    with process.helper_recorder(True) as helper:
        assert isinstance(helper, process.RecorderProcess) and helper._proc.poll() is None
    assert helper._proc.poll() == 0  # ended on leaving the block
