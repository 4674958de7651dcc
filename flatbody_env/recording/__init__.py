"""Rerun recordings (``.rrd``) of scenes and environment episodes for offline playback."""
