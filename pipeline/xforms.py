"""Transform helpers: axis/unit conversion, TRS (de)composition, quaternions.

All matrices are ``float64`` 4x4, column-vector convention (``p' = M @ p``).
Quaternions are ``(..., 4)`` arrays ordered ``(w, x, y, z)`` (real part first, as ``Gf.Quat``).
"""

from __future__ import annotations

import numpy as np

AXES = ("Y", "Z")


def axis_conversion(src_up: str, dst_up: str, src_mpu: float = 1.0, dst_mpu: float = 1.0) -> np.ndarray:
    """The 4x4 that takes points from a ``src_up``-up space in ``src_mpu`` metres per unit to a
    ``dst_up``-up space in ``dst_mpu`` metres per unit (right-handed, rotation about X)."""
    r = np.eye(4)
    if src_up == "Z" and dst_up == "Y":  # (x, y, z) -> (x, z, -y)
        r[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    elif src_up == "Y" and dst_up == "Z":  # (x, y, z) -> (x, -z, y)
        r[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    elif src_up != dst_up:
        raise ValueError(f"unsupported up axes {src_up!r} -> {dst_up!r}")
    s = np.eye(4)
    s[:3, :3] *= float(src_mpu) / float(dst_mpu)
    return r @ s


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) (w, x, y, z) quaternions -> (..., 3, 3) rotation matrices (normalises q)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (w, x, y, z), w >= 0."""
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    # Shepperd's method: pick the largest of the four squared components for stability.
    cand = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    k = np.argmax(cand, axis=-1)
    s = np.sqrt(np.maximum(np.take_along_axis(cand, k[..., None], -1)[..., 0], 1e-300)) * 2
    q = np.empty(r.shape[:-2] + (4,))
    w = r[..., 2, 1] - r[..., 1, 2]
    x = r[..., 0, 2] - r[..., 2, 0]
    y = r[..., 1, 0] - r[..., 0, 1]
    a = r[..., 0, 1] + r[..., 1, 0]
    b = r[..., 0, 2] + r[..., 2, 0]
    c = r[..., 1, 2] + r[..., 2, 1]
    q0 = np.stack([s / 4, w / s, x / s, y / s], -1)
    q1 = np.stack([w / s, s / 4, a / s, b / s], -1)
    q2 = np.stack([x / s, a / s, s / 4, c / s], -1)
    q3 = np.stack([y / s, b / s, c / s, s / 4], -1)
    q = np.choose(k[..., None], [q0, q1, q2, q3])
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def compose_trs(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Translation (..., 3), rotation quaternion (..., 4) and scale (..., 3) -> (..., 4, 4) = T R S."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros(t.shape[:-1] + (4, 4))
    out[..., :3, :3] = quat_to_matrix(q) * np.asarray(s, dtype=np.float64)[..., None, :]
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def decompose_trs(m: np.ndarray):
    """(..., 4, 4) affine matrices -> (t (..., 3), q (..., 4), s (..., 3)) with ``m = T R S``.

    Shear, if any, is dropped (the rotation is the orthonormal polar factor).  A negative
    determinant becomes a negative x scale.
    """
    m = np.asarray(m, dtype=np.float64)
    a = m[..., :3, :3]
    u, sig, vt = np.linalg.svd(a)
    rot = u @ vt
    det = np.linalg.det(rot)
    flip = det < 0
    s = np.linalg.norm(a, axis=-2)  # column norms
    if np.any(flip):
        rot = rot.copy()
        rot[flip, :, 0] *= -1
        s = s.copy()
        s[flip, 0] *= -1
    # Re-derive the scale along the rotation's own axes: s_i = (R^T A)_ii
    s = np.einsum("...ji,...ji->...i", rot, a)
    return m[..., :3, 3].copy(), matrix_to_quat(rot), s


def apply_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (n, 3) points; returns float64 (n, 3)."""
    p = np.asarray(p, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


def uniform_scale(m: np.ndarray) -> np.ndarray:
    """Largest axis scale of (..., 4, 4) transforms (what a sphere radius is multiplied by)."""
    return np.max(np.linalg.norm(np.asarray(m)[..., :3, :3], axis=-2), axis=-1)
