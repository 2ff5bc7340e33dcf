"""How far a collision proxy strays from the full skinned mesh: :func:`deviation`.

On the bind pose and every frame of every clip (:class:`Poses`, :func:`mesh_poses`), both meshes (their
blend shapes applied first at the clip's weights: the proxy carries the full mesh's,
:func:`colossus.pipeline.geometry.transfer.transfer_shapes`) are skinned
(:func:`colossus.runtime.kernels.skin.skin_frames`, the one skinning kernel, once per pose for both
directions) and the two-sided distance between the skinned surfaces is bounded from above by
:func:`colossus.pipeline.geometry.surface_distance.deviation_bound` (a Lipschitz bound and a convexity
bound per piece, pieces subdivided where they are more than ``DEVIATION_REFINE`` above the largest
distance found), plus ``DEVIATION_PAD * size`` for float32 rounding.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from colossus.runtime.kernels.skin import skin_frames

from ..model import SkinnedMesh, skel_transforms
from ..tolerances import DEVIATION_MAX_DEPTH, DEVIATION_PAD, DEVIATION_REFINE, DEVIATION_RESOLUTION, model_scale
from .surface_distance import deviation_bound

#: Candidate triangles per sample: of the dense full mesh (proxy -> full, the weight transfer) ...
FULL_CANDIDATES = 16
#: ... and of the coarse proxy (full -> proxy).
PROXY_CANDIDATES = 8
#: Skinned poses kept in memory by the deviation when they fit in this many bytes.
SKIN_CACHE_BYTES = 512 * 2 ** 20


@dataclass
class Poses:
    """The poses the deviation covers: the bind pose, then every frame of every clip.

    mats : (F, b, 4, 4) float64 skinning matrices (``skel @ inv(bind) @ geom_bind``: mesh space
    to skeleton space); clip : list of clip name (None for the bind pose); frame : (F,) int;
    time : (F,) float64 time codes (nan for the bind pose); weights : (F, S) float64 blend-shape
    weights at each pose (0 at the bind pose; S = 0 without shapes)."""

    mats: np.ndarray
    clip: list
    frame: np.ndarray
    time: np.ndarray
    weights: np.ndarray = None

    def __post_init__(self):
        if self.weights is None:
            self.weights = np.zeros((len(self.mats), 0))

    def label(self, i: int) -> str:
        return "bind pose" if self.clip[i] is None else f"{self.clip[i]} frame {int(self.frame[i])}"

    def subset(self, idx) -> "Poses":
        idx = np.asarray(idx)
        return Poses(self.mats[idx], [self.clip[i] for i in idx], self.frame[idx], self.time[idx], self.weights[idx])


def mesh_poses(mesh: SkinnedMesh) -> Poses:
    """:class:`Poses` of ``mesh``: its bind pose and every frame of every clip."""
    inv_bind = np.linalg.inv(mesh.bind_transforms)
    skel = [mesh.bind_transforms[None]]
    clip, frame, times = [None], [0], [np.nan]
    weights = [np.zeros((1, len(mesh.blend_shapes)))]
    for c in mesh.clips:
        skel.append(skel_transforms(c.local, mesh.parents))
        clip += [c.name] * c.frame_count
        frame += list(range(c.frame_count))
        times += list(c.times)
        weights.append(np.asarray(c.shape_weights, dtype=np.float64).reshape(c.frame_count, -1))
    S = np.concatenate(skel)
    mats = S @ inv_bind[None] @ mesh.geom_bind
    return Poses(np.ascontiguousarray(mats), clip, np.array(frame, np.int64), np.array(times, np.float64),
                 np.concatenate(weights) if mesh.blend_shapes else None)


def rest_skel(mesh: SkinnedMesh) -> np.ndarray:
    G = mesh.geom_bind
    return mesh.positions.astype(np.float64) @ G[:3, :3].T + G[:3, 3]


def _chunks(F: int, vertices: int, budget: int = 8_000_000):
    """Pose indices ``0..F-1`` in chunks whose skinned vertices stay under ~100 MB."""
    step = max(1, int(budget // max(1, 3 * vertices)))
    return [np.arange(i, min(F, i + step)) for i in range(0, F, step)]


@dataclass
class Deviation:
    """The two-sided deviation bound between a proxy and the full mesh.

    bound : float, stage units (max over poses and both directions, pad included)
    pose_bound : (F,) float64, an upper bound of the deviation at each pose (pad included)
    sampled : float, the largest distance actually measured between the surfaces (a sample point
        and its nearest candidate triangle: the truth, from below, unless a candidate list
        missed the nearest triangle); the bound is at most ``sampled * (1 + refine)`` plus the
        resolution wherever the subdivision depth sufficed
    pose_sampled : (F,) float64, the largest distance measured at each pose
    worst_pose : int, worst_joint : int, direction : str
        Where ``sampled`` was measured: the pose, the dominant joint of the sample's vertex, and
        ``"full->proxy"`` (a point of the full surface far from the proxy) or ``"proxy->full"``
    samples : int, sample points made (both directions)
    exceeded : bool, a ``decide`` run stopped at a distance above its limit
    directions : {"full->proxy": OneSided, "proxy->full": OneSided}
    """

    bound: float
    pose_bound: np.ndarray
    sampled: float
    pose_sampled: np.ndarray
    worst_pose: int
    worst_joint: int
    direction: str
    samples: int
    exceeded: bool = False
    directions: dict = field(default_factory=dict)


def dominant_joint(mesh: SkinnedMesh, v: int) -> int:
    """The strongest joint of vertex ``v``."""
    return int(mesh.joint_indices[v][int(np.argmax(mesh.joint_weights[v]))])


def deviation(full: SkinnedMesh, proxy: SkinnedMesh, poses: Poses | None = None,
              refine: float = DEVIATION_REFINE, limit: float | None = None, decide: bool = False) -> Deviation:
    """Upper bound of the two-sided distance between the skinned surfaces of ``full`` and
    ``proxy`` (same skeleton) on every pose.

    Parameters
    ----------
    full, proxy : SkinnedMesh
    poses : Poses, optional (default :func:`mesh_poses` of ``full``: bind pose and every frame);
        its first pose is where candidates are chosen (the bind pose in :func:`mesh_poses`)
    refine : float
        Pieces are subdivided while their bound is more than this fraction above the largest
        sampled distance (see :func:`pipeline.geometry.surface_distance.deviation_bound`).
    limit : float, optional
        Subdivide until the bound is within ``limit`` where possible.
    decide : bool
        Only decide ``bound <= limit`` (cheaper; ``exceeded`` says no).

    Returns
    -------
    Deviation
    """
    poses = poses or mesh_poses(full)
    size = model_scale(rest_skel(full))
    if full.skinning_method != "classicLinear":  # the one kernel's layout for the mesh's method
        from colossus.runtime.kernels.skin import fold_method
        G = full.geom_bind
        poses = Poses(fold_method(full.skinning_method, poses.mats @ np.linalg.inv(G), G), poses.clip, poses.frame,
                      poses.time, poses.weights)
    # blend shapes (the proxy carries the full mesh's, transferred): each pose's points displaced by
    # them first, as UsdSkel and the one kernel skin them
    shaped = bool(full.blend_shapes) and poses.weights.shape[1] == len(full.blend_shapes) and np.any(poses.weights)
    if shaped:
        from colossus.runtime.kernels.skin import shape_points

        from ..model import kernel_shapes
        ks_a, ks_b = kernel_shapes(full.blend_shapes, full.vertex_count), kernel_shapes(proxy.blend_shapes,
                                                                                          proxy.vertex_count)

    def pts(mesh, ks, idx):
        return shape_points(mesh.positions, ks, poses.weights[idx]) if shaped else mesh.positions
    F = len(poses.mats)
    nv = full.vertex_count + proxy.vertex_count
    cache = {}
    if F * nv * 12 <= SKIN_CACHE_BYTES:  # every pose skinned once, in a few kernel calls
        cache["a"] = np.empty((F, full.vertex_count, 3), np.float32)
        cache["b"] = np.empty((F, proxy.vertex_count, 3), np.float32)
        for ch in _chunks(F, nv):
            cache["a"][ch] = skin_frames(pts(full, ks_a if shaped else None, ch), full.joint_indices,
                                         full.joint_weights, poses.mats[ch])
            cache["b"][ch] = skin_frames(pts(proxy, ks_b if shaped else None, ch), proxy.joint_indices,
                                         proxy.joint_weights, poses.mats[ch])

    def frames(idx):
        if cache:
            if len(idx) and idx[-1] - idx[0] == len(idx) - 1:  # a run of poses: views, no copy
                return cache["a"][idx[0]:idx[-1] + 1], cache["b"][idx[0]:idx[-1] + 1]
            return cache["a"][idx], cache["b"][idx]
        m = poses.mats[idx]
        return (skin_frames(pts(full, ks_a if shaped else None, idx), full.joint_indices, full.joint_weights, m),
                skin_frames(pts(proxy, ks_b if shaped else None, idx), proxy.joint_indices, proxy.joint_weights, m))

    pad = DEVIATION_PAD * size
    a, b = deviation_bound(frames, F, full.triangles, proxy.triangles, refine, DEVIATION_RESOLUTION * size,
                           candidates=(PROXY_CANDIDATES, FULL_CANDIDATES), max_depth=DEVIATION_MAX_DEPTH,
                           limit=None if limit is None else limit - pad, decide=decide)
    worst, src, direction = (a, full, "full->proxy") if a.sampled >= b.sampled else (b, proxy, "proxy->full")
    return Deviation(bound=max(a.bound, b.bound) + pad, pose_bound=np.maximum(a.pose_bound, b.pose_bound) + pad,
                     sampled=worst.sampled, pose_sampled=np.maximum(a.pose_sampled, b.pose_sampled),
                     worst_pose=worst.sampled_pose, worst_joint=dominant_joint(src, worst.sampled_vertex),
                     direction=direction, samples=a.samples + b.samples, exceeded=a.exceeded or b.exceeded,
                     directions={"full->proxy": a, "proxy->full": b})
