"""A node-graph reader's scene: the records it fills (:class:`Scene`, :class:`SceneMesh`,
:class:`Skin`, :class:`Animation`, :class:`Channel`), the world transforms of its hierarchy
(:func:`_world`) and what :func:`~colossus.pipeline.readers.scene.build.build` assumes of it, checked
once for every format (:func:`check_scene`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...tolerances import DEGENERATE_RATIO, LARGEST_COORDINATE
from ...xforms import degenerate

#: a channel's interpolation between keys: glTF's three, and ``NLERP`` (translation and scale
#: linear, rotation by normalised lerp along the shortest path: Ogre's default ``RIM_LINEAR``)
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE", "NLERP")


@dataclass
class Skin:
    """A mesh's skin.

    Attributes
    ----------
    joints : (b,) int64
        Node index of each skin joint (``-1``: a bone with no node in the scene).
    inverse_binds : (b, 4, 4) float64
        Mesh space at bind time -> joint space (glTF ``inverseBindMatrices``, assimp offsets).
    names : list of str
        Name of each skin joint (used for bones without a node).
    vertex, joint : (e,) int64, weight : (e,) float64
        Flat influences: ``joint`` indexes ``joints``.
    """

    joints: np.ndarray
    inverse_binds: np.ndarray
    names: list
    vertex: np.ndarray
    joint: np.ndarray
    weight: np.ndarray


@dataclass
class SceneMesh:
    """One mesh of the scene.

    Attributes
    ----------
    name : str
    node : int
        Node holding the mesh (-1: none).
    positions : (n, 3) float64
        In mesh space.
    triangles : (m, 3) int64
    to_world : (4, 4) float64
        Mesh space -> world space at bind time (for a skinned mesh the transform its skin's
        inverse binds are relative to: identity for glTF, whose skinned meshes ignore their
        node's transform; the node's world transform otherwise).
    skin : Skin or None
    morph_targets : int
        Number of morph targets / shape keys the source has.
    shapes : list of model.BlendShape
        Its blend shapes (morph targets), carried: mesh-local point indices, mesh-space offsets.
    """

    name: str
    node: int
    positions: np.ndarray
    triangles: np.ndarray
    to_world: np.ndarray
    skin: Skin | None = None
    morph_targets: int = 0
    shapes: list = field(default_factory=list)


@dataclass
class Channel:
    """The keys of one node's translation (``"t"``), rotation (``"r"``, x y z w) or scale (``"s"``).

    ``values`` is ``(k, c)``, or ``(k, 3, c)`` for CUBICSPLINE (in-tangent, value, out-tangent).
    ``times`` are seconds.
    """

    node: int
    path: str
    times: np.ndarray
    values: np.ndarray
    interpolation: str = "LINEAR"
    static: bool = False  #: a single unanimated value (USD default): no key time of the clip


@dataclass
class Animation:
    """One animation: its channels, and optionally its own span ``(start, stop)`` in seconds
    (an FBX stack's range; keys outside it are not part of the clip)."""

    name: str
    channels: list
    span: tuple | None = None
    #: blend-shape weight channels: :class:`Channel` with ``node`` the index of the scene mesh
    #: whose shapes it drives, ``path`` ``"w"`` and one value column per shape of that mesh
    weights: list = field(default_factory=list)


@dataclass
class Scene:
    """What a node-graph reader found in the file.

    Attributes
    ----------
    names : list of str
    parents : (k,) int64, parents first (each parent index lower than its child), -1 for roots
    local : (k, 4, 4) float64 rest local transforms
    meshes : list of SceneMesh
    animations : list of Animation
    helpers : set of int
        Nodes never made joints by themselves (FBX pivot helpers), folded into their neighbours.
    unweighted_follow_node : bool
        The format's rule for a skinned mesh's vertices without any weight: they stay with the
        mesh's node (FBX, Collada: an armature deforms only weighted vertices), bound rigidly to
        the joint that node moves with.  Otherwise they are left unweighted for ``bind`` to judge.
    no_parent_scale : dict
        ``{node: scale node}``: nodes that do not inherit their parent's scale (FBX
        ``InheritType`` 2, Maya's segment scale compensation): ``world = parent_world @ T @
        inv(S_parent) @ R @ S``, with ``S_parent`` the scale of the ``scale node``'s local transform.
    fps_hint : float or None
        The file's own declared frame rate (FBX header), tried first for the grid.
    sampling_note : str
        How the reader obtained the keys (for the summary).
    notes : list of str
        The reader's own findings, for the import's warnings.
    """

    names: list
    parents: np.ndarray
    local: np.ndarray
    meshes: list
    animations: list
    helpers: set = field(default_factory=set)
    fps_hint: float | None = None
    sampling_note: str = ""
    unweighted_follow_node: bool = False
    no_parent_scale: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


def _world(local, parents, no_parent_scale=None):
    """World transforms of nodes in parents-first order; ``local`` is (..., k, 4, 4).

    ``no_parent_scale`` ``{node: scale node}``: those nodes compose as
    ``parent_world @ T @ inv(S) @ (R S)`` with ``S`` the scale of ``local[scale node]`` (FBX
    segment scale compensation), i.e. their local's 3x3 left-multiplied by ``inv(S)``."""
    out = np.empty_like(local)
    rrs = no_parent_scale or {}
    for i, p in enumerate(parents):
        m = local[..., i, :, :]
        if i in rrs:
            s = np.linalg.norm(local[..., rrs[i], :3, :3], axis=-2)  # (..., 3) axis scales of the parent's local
            m = m.copy()
            m[..., :3, :3] = m[..., :3, :3] / s[..., :, None]
        out[..., i, :, :] = m if p < 0 else out[..., p, :, :] @ m
    return out


def _ancestors(parents, i):
    out = []
    p = parents[i]
    while p >= 0:
        out.append(int(p))
        p = parents[p]
    return out


_BAD_XFORM = "is not finite, not invertible (zero scale?) or huge"


def _bounded(a) -> bool:
    """Every entry finite and within +-LARGEST_COORDINATE (never warns)."""
    with np.errstate(invalid="ignore"):
        return bool(np.all(np.abs(np.asarray(a, dtype=np.float64)) <= LARGEST_COORDINATE))


def check_scene(scene: Scene, path) -> None:
    """What :func:`~.build.build` assumes of a reader's scene, checked once for every node-graph format
    (a corrupt or hostile file otherwise ends in a singular-matrix failure, a NaN warning or an
    index error inside the builder).  Raises :class:`InputError` naming ``path`` and the part:
    node transforms and the world transforms they compose to, mesh points and triangles, skin
    indices, weights and inverse binds, channel key times (finite, increasing) and values
    (finite, bounded, non-zero rotations, invertible scales) and animation spans."""
    names, k = scene.names, len(scene.names)
    parents = np.asarray(scene.parents, dtype=np.int64)
    local = np.asarray(scene.local, dtype=np.float64)
    if local.shape != (k, 4, 4) or parents.shape != (k,) or np.any(parents >= np.arange(k)) or np.any(parents < -1):
        raise InputError(path, "the node hierarchy is inconsistent (parents must come before their children)")
    bad = np.flatnonzero(degenerate(local))
    if not len(bad):
        with np.errstate(all="ignore"):  # an overflow to inf is caught by degenerate()
            bad = np.flatnonzero(degenerate(_world(local, parents, scene.no_parent_scale)))
    if len(bad):
        raise InputError(path, f"the transform of node {names[bad[0]]!r} {_BAD_XFORM}")
    for m in scene.meshes:
        nv = len(m.positions)
        if not _bounded(m.positions):
            raise InputError(path, f"mesh {m.name!r}: vertex positions are not finite or beyond +-{LARGEST_COORDINATE:g}")
        if len(m.triangles) and (m.triangles.min() < 0 or m.triangles.max() >= nv):
            raise InputError(path, f"mesh {m.name!r}: a face vertex index is out of range for {nv} vertices")
        if m.node >= k or degenerate(np.asarray(m.to_world, dtype=np.float64)):
            raise InputError(path, f"mesh {m.name!r}: its node or mesh-to-world transform {_BAD_XFORM}")
        sk = m.skin
        if sk is None:
            continue
        nb = len(sk.joints)
        if (len(sk.inverse_binds) != nb or (nb and (sk.joints.max() >= k or sk.joints.min() < -1))
                or not len(sk.vertex) == len(sk.joint) == len(sk.weight)):
            raise InputError(path, f"mesh {m.name!r}: its skin's joints, inverse binds and weights do not match")
        if len(sk.vertex) and (sk.vertex.min() < 0 or sk.vertex.max() >= nv or sk.joint.min() < 0 or sk.joint.max() >= nb):
            raise InputError(path, f"mesh {m.name!r}: a skin weight names a vertex or joint out of range")
        with np.errstate(invalid="ignore"):
            if not np.all((sk.weight >= 0) & (sk.weight <= LARGEST_COORDINATE)):
                raise InputError(path, f"mesh {m.name!r}: skin weights are negative, not finite or huge")
        bad = np.flatnonzero(degenerate(np.asarray(sk.inverse_binds, dtype=np.float64)))
        if len(bad):
            raise InputError(path, f"mesh {m.name!r}: the inverse bind matrix of joint {sk.names[bad[0]]!r} {_BAD_XFORM}")
    if scene.fps_hint is not None and not (np.isfinite(scene.fps_hint) and scene.fps_hint <= 1e6):
        scene.fps_hint = None  # a corrupt declared rate: the grid comes from the keys
    for a in scene.animations:
        if a.span is not None and not (_bounded(a.span) and a.span[0] <= a.span[1]):
            raise InputError(path, f"animation {a.name!r}: its time span {a.span} is not finite or reversed")
        for c in a.channels:
            what = f"animation {a.name!r}: node {names[c.node] if 0 <= c.node < k else c.node!r}"
            t = np.asarray(c.times, dtype=np.float64)
            v = np.asarray(c.values, dtype=np.float64)
            width = {"t": 3, "r": 4, "s": 3}.get(c.path)
            cubic = c.interpolation == "CUBICSPLINE"
            if (not 0 <= c.node < k or width is None or c.interpolation not in INTERPOLATIONS
                    or v.shape != ((len(t), 3, width) if cubic else (len(t), width))):
                raise InputError(path, f"{what}: a channel's keys do not match its times ({v.shape} values "
                                 f"for {len(t)} keys)")
            if not _bounded(t) or np.any(np.diff(t) < 0):
                raise InputError(path, f"{what}: key times are not finite, huge or not increasing")
            if not _bounded(v):
                raise InputError(path, f"{what}: animation values are not finite or beyond +-{LARGEST_COORDINATE:g}")
            vals = v[:, 1] if cubic else v
            if c.path == "r" and len(vals):
                n = np.linalg.norm(vals, axis=1)
                if np.any(n < 1e-6):
                    raise InputError(path, f"{what}: a rotation key is a zero quaternion")
            if c.path == "s" and len(vals) and np.any(np.abs(vals).min(axis=1) <= DEGENERATE_RATIO * np.abs(vals).max(axis=1)):
                key = int(np.argmax(np.abs(vals).min(axis=1) <= DEGENERATE_RATIO * np.abs(vals).max(axis=1)))
                raise InputError(path, f"{what}: the scale key at {t[key]:g} s is zero or degenerate "
                                 f"({', '.join(f'{x:g}' for x in vals[key])}): joint space is not defined there")
