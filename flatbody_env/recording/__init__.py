"""Rerun recordings (``.rrd``) of scenes and environment episodes for offline playback.

One module per concept: :mod:`~flatbody_env.recording.geometry` (pure numpy),
:mod:`~flatbody_env.recording.layout` (views, names, colours, description),
:mod:`~flatbody_env.recording.writer` (:class:`Recorder`, :func:`record_trajectory`),
:mod:`~flatbody_env.recording.wrapper` (:class:`RerunRecorder`, the one way to record an env
episode), :mod:`~flatbody_env.recording.reader` (read back, blueprint, verify, summarize) and
:mod:`~flatbody_env.recording.viewer` (screenshots in the real viewer). The names below are loaded
on first use, so importing this package imports neither rerun nor gymnasium.
"""

from __future__ import annotations

_HOMES = {
    "Recorder": "writer",
    "record_arrays": "writer",
    "record_trajectory": "writer",
    "RerunRecorder": "wrapper",
    "read_recording": "reader",
    "read_blueprint": "reader",
    "summarize_recording": "reader",
    "verify_recording": "reader",
    "screenshots": "viewer",
}


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'flatbody_env.recording' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"flatbody_env.recording.{home}"), name)


__all__ = sorted(_HOMES)
