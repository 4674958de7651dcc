"""Geometry of recordings: quaternions of R against scipy's independent conversion."""

from __future__ import annotations

import numpy as np

from flatbody_env.recording.geometry import quaternions_xyzw, rotation_from_quaternions


def test_quaternions_against_an_independent_conversion():
    from scipy.spatial.transform import Rotation

    rot = Rotation.random(500, random_state=1)
    extra = Rotation.from_rotvec(
        np.array([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [np.pi / np.sqrt(2), np.pi / np.sqrt(2), 0], [0, 0, 0]])
    )
    R = np.concatenate([rot.as_matrix(), extra.as_matrix()])
    q = quaternions_xyzw(R)
    ref = Rotation.from_matrix(R).as_quat()
    sign = np.sign(np.sum(q * ref, axis=1))
    np.testing.assert_allclose(q, ref * sign[:, None], atol=1e-12)
    np.testing.assert_allclose(rotation_from_quaternions(q), R, atol=1e-12)
