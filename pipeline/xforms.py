"""Transform helpers: axis/unit conversion, TRS (de)composition, quaternions.

All matrices are ``float64`` 4x4, column-vector convention (``p' = M @ p``).
Quaternions are ``(..., 4)`` arrays ordered ``(x, y, z, w)`` (scalar last: pxr's numpy order and
scipy's), converted and interpolated by scipy's ``Rotation`` (the runtime's numba kernels keep a
hand-written GfSlerp port, since scipy cannot be called from compiled code).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

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
    """(..., 4) (x, y, z, w) quaternions -> (..., 3, 3) rotation matrices (q is normalised)."""
    q = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (x, y, z, w), w >= 0."""
    r = np.asarray(r, dtype=np.float64)
    return Rotation.from_matrix(r.reshape(-1, 3, 3)).as_quat(canonical=True).reshape(r.shape[:-2] + (4,))


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc between (..., 4) (x, y, z, w)
    quaternions by fractions ``u`` (...,) in [0, 1] (what glTF LINEAR and UsdSkel do)."""
    q0 = np.asarray(q0, dtype=np.float64)
    shape = q0.shape
    r0 = Rotation.from_quat(q0.reshape(-1, 4))
    step = (r0.inv() * Rotation.from_quat(np.asarray(q1, dtype=np.float64).reshape(-1, 4))).as_rotvec()
    u = np.broadcast_to(np.asarray(u, dtype=np.float64), shape[:-1]).reshape(-1, 1)
    return (r0 * Rotation.from_rotvec(step * u)).as_quat().reshape(shape)


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
    determinant becomes a negative x scale.  Matrices that are exactly ``T R S`` (columns
    orthogonal) take a fast path (column norms); the others the SVD.
    """
    m = np.asarray(m, dtype=np.float64)
    a = m[..., :3, :3]
    s = np.linalg.norm(a, axis=-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        rot = a / s[..., None, :]
    gram = np.swapaxes(rot, -1, -2) @ rot
    sheared = ~np.all(np.abs(gram - np.eye(3)) <= 1e-10, axis=(-2, -1))
    if np.any(sheared):
        u, _, vt = np.linalg.svd(a[sheared])
        rot = rot.copy()
        rot[sheared] = u @ vt
    det = np.linalg.det(rot)
    flip = det < 0
    if np.any(flip):
        rot = rot.copy()
        rot[flip, :, 0] *= -1
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
