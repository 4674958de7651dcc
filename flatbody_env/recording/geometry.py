"""Pure-numpy geometry of what a recording draws: quaternions of R, the six entries of symmetric
tensors, the static material lines.

No rerun here: these are the conversions the writer uses and the reader's checks invert.
"""

from __future__ import annotations

import numpy as np

TENSOR_ENTRIES = ("11", "22", "33", "12", "13", "23")
"""Order of the six independent entries of the symmetric G and C in ``/series/G``, ``/series/C``."""


def relative_drift(q: np.ndarray, q0: float) -> np.ndarray:
    """(q − q₀)/|q₀|, or q − q₀ where q₀ = 0: the drift of a conserved quantity, shape of ``q``."""
    q = np.asarray(q, dtype=np.float64)
    return (q - q0) / abs(q0) if q0 != 0.0 else q - q0


def principal_axes(frames: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Arrow vectors (n, 3, 3) — row i: column i of ``frames`` (n, 3, 3) times the semi-axis ``half[:, i]``.

    With ``frames`` = R these are the principal axes of C = R D⁻² Rᵀ in the laboratory; with U(θ)
    those of G = U D² Uᵀ in the material frame (eqs. (23), (33) of the paper). Length = λ, μ, ϱ.
    """
    return np.swapaxes(np.asarray(frames) * np.asarray(half)[:, None, :], 1, 2)


def unit_circle(segments: int = 96) -> np.ndarray:
    """Closed unit circle in the x–y plane, shape (segments + 1, 3)."""
    a = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    return np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)


def quaternions_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices ``R`` of shape (n, 3, 3) → (n, 4).

    Shepperd's method, vectorized; the branch with the largest pivot is taken per row.
    """
    R = np.asarray(R, dtype=np.float64)
    n = R.shape[0]
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    pivots = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    which = np.argmax(pivots, axis=1)
    q = np.empty((n, 4))
    # w largest
    m = which == 0
    s = np.sqrt(np.maximum(1.0 + tr[m], 0.0)) * 2.0
    q[m, 3] = 0.25 * s
    q[m, 0] = (R[m, 2, 1] - R[m, 1, 2]) / s
    q[m, 1] = (R[m, 0, 2] - R[m, 2, 0]) / s
    q[m, 2] = (R[m, 1, 0] - R[m, 0, 1]) / s
    # x largest
    m = which == 1
    s = np.sqrt(np.maximum(1.0 + R[m, 0, 0] - R[m, 1, 1] - R[m, 2, 2], 0.0)) * 2.0
    q[m, 3] = (R[m, 2, 1] - R[m, 1, 2]) / s
    q[m, 0] = 0.25 * s
    q[m, 1] = (R[m, 0, 1] + R[m, 1, 0]) / s
    q[m, 2] = (R[m, 0, 2] + R[m, 2, 0]) / s
    # y largest
    m = which == 2
    s = np.sqrt(np.maximum(1.0 - R[m, 0, 0] + R[m, 1, 1] - R[m, 2, 2], 0.0)) * 2.0
    q[m, 3] = (R[m, 0, 2] - R[m, 2, 0]) / s
    q[m, 0] = (R[m, 0, 1] + R[m, 1, 0]) / s
    q[m, 1] = 0.25 * s
    q[m, 2] = (R[m, 1, 2] + R[m, 2, 1]) / s
    # z largest
    m = which == 3
    s = np.sqrt(np.maximum(1.0 - R[m, 0, 0] - R[m, 1, 1] + R[m, 2, 2], 0.0)) * 2.0
    q[m, 3] = (R[m, 1, 0] - R[m, 0, 1]) / s
    q[m, 0] = (R[m, 0, 2] + R[m, 2, 0]) / s
    q[m, 1] = (R[m, 1, 2] + R[m, 2, 1]) / s
    q[m, 2] = 0.25 * s
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_from_quaternions(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of quaternions (x, y, z, w) of shape (n, 4) (normalized first)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def symmetric_entries(M: np.ndarray) -> np.ndarray:
    """The six entries (11, 22, 33, 12, 13, 23) of symmetric matrices (n, 3, 3) → (n, 6)."""
    M = np.asarray(M)
    return np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], M[:, 0, 1], M[:, 0, 2], M[:, 1, 2]], axis=1)


def symmetric_from_entries(e: np.ndarray) -> np.ndarray:
    """Inverse of :func:`symmetric_entries`: (n, 6) → symmetric (n, 3, 3)."""
    e = np.asarray(e, dtype=np.float64)
    M = np.empty((e.shape[0], 3, 3))
    M[:, 0, 0], M[:, 1, 1], M[:, 2, 2] = e[:, 0], e[:, 1], e[:, 2]
    M[:, 0, 1] = M[:, 1, 0] = e[:, 3]
    M[:, 0, 2] = M[:, 2, 0] = e[:, 4]
    M[:, 1, 2] = M[:, 2, 1] = e[:, 5]
    return M


def material_lines(spokes: int = 12, segments: int = 96) -> list[np.ndarray]:
    """Static material lines in the reference frame: unit circle, ``spokes`` radii, the normal e₃.

    Drawn under Φ they become the ellipse's rim and the images of material fibres; the first
    spoke (the fibre along e₁) is the one to follow.
    """
    a = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    circle = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    strips = [circle]
    for k in range(spokes):
        b = 2.0 * np.pi * k / spokes
        strips.append(np.array([[0.0, 0.0, 0.0], [np.cos(b), np.sin(b), 0.0]]))
    strips.append(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]))
    return strips
