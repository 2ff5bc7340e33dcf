"""When a clip is sampled: channel sampling with each channel's own interpolation
(:func:`sample_channel`), the frame grid (:func:`choose_fps`, :func:`grid_frames`), the joint
locals at given times (:func:`_joint_locals`) and the error bound of a clip whose keys fall
between frames (:func:`_resampling_bound`)."""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...model import skel_transforms
from ...tolerances import GRID_KEY_FRAMES
from ...xforms import compose_trs, decompose_trs, degenerate, slerp
from .graph import _BAD_XFORM, Channel, _world

#: Frame rates tried, in order, for a file's own grid: the first on which every key falls wins.
GRID_RATES = (24.0, 30.0, 25.0, 60.0, 48.0, 50.0, 120.0, 23.976, 29.97, 59.94, 90.0, 100.0, 240.0,
              12.0, 15.0, 10.0, 8.0)
#: The grid's rate when no rate holds the keys (the contract's default).
DEFAULT_FPS = 30.0
#: Longest clip, in grid frames (a corrupt key time must not make the grid itself the allocation).
MAX_FRAMES = 10_000_000


def sample_channel(ch: Channel, seconds: np.ndarray, key_tolerance: float = 0.0) -> np.ndarray:
    """The channel's value at ``seconds`` (clamped to its first and last key), with its own
    interpolation.  Returns ``(f, c)`` float64; rotations are unit quaternions (x, y, z, w).

    A sample within ``key_tolerance`` seconds of a key takes that key's value exactly (no
    interpolation round-off; a file's float32 key times are never bit-equal to ``frame / fps``)."""
    t = np.asarray(ch.times, dtype=np.float64)
    v = np.asarray(ch.values, dtype=np.float64)
    cubic = ch.interpolation == "CUBICSPLINE"
    vals = v[:, 1] if cubic else v
    seconds = np.asarray(seconds, dtype=np.float64)
    if len(t) == 1:
        return np.repeat(vals[:1], len(seconds), axis=0)
    j = np.minimum(np.searchsorted(t, seconds - key_tolerance), len(t) - 1)
    on = np.abs(t[j] - seconds) <= key_tolerance
    if np.all(on):
        return vals[j]
    out = np.empty((len(seconds), vals.shape[1]))
    out[on] = vals[j[on]]
    x = seconds[~on]
    i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    t0, t1 = t[i], t[i + 1]
    dt = np.where(t1 > t0, t1 - t0, 1.0)
    u = np.clip((x - t0) / dt, 0.0, 1.0)
    if ch.interpolation == "STEP":
        res = np.where((u >= 1.0)[:, None], vals[i + 1], vals[i])
    elif cubic:  # glTF 2.0 spec, Appendix C: Hermite spline with tangents scaled by the key interval
        u2, u3 = u * u, u * u * u
        h00, h10 = 2 * u3 - 3 * u2 + 1, u3 - 2 * u2 + u
        h01, h11 = -2 * u3 + 3 * u2, u3 - u2
        res = (h00[:, None] * v[i, 1] + (h10 * dt)[:, None] * v[i, 2]
               + h01[:, None] * v[i + 1, 1] + (h11 * dt)[:, None] * v[i + 1, 0])
        if ch.path == "r":  # tangents that cancel the value would divide by zero: hold the key there
            n = np.linalg.norm(res, axis=1, keepdims=True)
            res = np.where(n > 1e-12, res / np.where(n > 1e-12, n, 1.0), vals[i])
    elif ch.path == "r" and ch.interpolation == "NLERP":  # Ogre's RIM_LINEAR: lerp, shortest path, normalise
        b = np.where((np.sum(vals[i] * vals[i + 1], axis=1) < 0)[:, None], -vals[i + 1], vals[i + 1])
        res = vals[i] + (b - vals[i]) * u[:, None]
        n = np.linalg.norm(res, axis=1, keepdims=True)
        res = np.where(n > 1e-12, res / np.where(n > 1e-12, n, 1.0), vals[i])
    elif ch.path == "r":
        res = slerp(vals[i], vals[i + 1], u)
    else:
        res = vals[i] + (vals[i + 1] - vals[i]) * u[:, None]
    out[~on] = res
    return out


def _off_grid(seconds: np.ndarray, fps: float) -> np.ndarray:
    f = np.asarray(seconds, dtype=np.float64) * fps
    return np.abs(f - np.round(f)) > GRID_KEY_FRAMES


def choose_fps(key_seconds: list, hint: float | None = None) -> float:
    """The grid rate for clips whose keys are at ``key_seconds`` (one array per clip).

    The file's declared rate ``hint`` if every key falls on it, else the first of
    :data:`GRID_RATES` that holds every key, else the source's own regular grid (any rate: 37
    fps, say), read off its keys (:func:`_own_rate`), else the list's rate holding the most clips
    (ties: earlier in the list), else :data:`DEFAULT_FPS`.
    """
    clips = [np.asarray(k, dtype=np.float64) for k in key_seconds if len(k) > 1]
    rates = ((float(hint),) if hint and hint > 0 else ()) + GRID_RATES
    if not clips:
        return float(hint) if hint and hint > 0 else 24.0
    best, best_n = None, 0
    for r in rates:
        n = sum(not np.any(_off_grid(k, r)) for k in clips)
        if n == len(clips):
            return r
        if n > best_n:
            best, best_n = r, n
    own = _own_rate(clips)
    if own is not None:
        return own
    return best if best is not None else DEFAULT_FPS


#: Highest rate :func:`_own_rate` reads off a file's keys (the list's highest; finer spacing is not
#: taken for a frame grid: a clip would be sampled into too many frames).
MAX_OWN_RATE = 240.0


def _own_rate(clips) -> float | None:
    """The rate of the regular grid every key of every clip sits on, read off the keys: one over
    the smallest spacing between consecutive keys, rounded to 1e-6 of itself (a file's float32
    times), when every key falls on it (:func:`_off_grid`) and it is at most
    :data:`MAX_OWN_RATE`; else None.  A grid the keys use every other frame of is still theirs:
    no key is resampled."""
    gaps = np.concatenate([np.diff(np.unique(k)) for k in clips])
    gaps = gaps[gaps > 0]
    if not len(gaps):
        return None
    r = 1.0 / float(gaps.min())
    if not (np.isfinite(r) and 0 < r <= MAX_OWN_RATE):
        return None
    digits = max(0, 6 - int(np.floor(np.log10(r))) - 1)
    r = round(r, digits)
    return r if all(not np.any(_off_grid(k, r)) for k in clips) else None


def grid_frames(seconds: np.ndarray, fps: float) -> np.ndarray:
    """Whole frame numbers from the frame at or before the first key to the one at or after the last."""
    f = np.asarray(seconds, dtype=np.float64) * fps
    f0 = int(np.floor(f.min() + GRID_KEY_FRAMES))
    f1 = int(np.ceil(f.max() - GRID_KEY_FRAMES))
    return np.arange(f0, max(f0, f1) + 1, dtype=np.float64)


def _joint_locals(seconds, chans, nlocal, static_t, static_q, static_s, sub, sub_of, sub_parents, jsub,
                  jparents, n_ghost, rest, sub_rrs=None, key_tol=0.0, path="", clip="", jnames=()):
    """(f, b, 4, 4) joint-local transforms at ``seconds``: node locals sampled, composed to world,
    made relative to each joint's parent joint (ghost joints hold their rest).  Raises
    :class:`InputError` (naming ``path``, ``clip`` and the joint) where a joint's world transform
    is degenerate (a scale through zero): joint space is not defined there."""
    f = len(seconds)
    loc = np.broadcast_to(nlocal[sub], (f, len(sub), 4, 4)).copy()
    by_node = {}
    for c in chans:
        by_node.setdefault(c.node, {})[c.path] = c
    if by_node:  # every animated node's TRS sampled, then composed in one call
        nodes = list(by_node)
        T = np.empty((f, len(nodes), 3))
        R = np.empty((f, len(nodes), 4))
        S = np.empty((f, len(nodes), 3))
        for x, node in enumerate(nodes):
            paths = by_node[node]
            T[:, x] = sample_channel(paths["t"], seconds, key_tol) if "t" in paths else static_t[node]
            R[:, x] = sample_channel(paths["r"], seconds, key_tol) if "r" in paths else static_q[node]
            S[:, x] = sample_channel(paths["s"], seconds, key_tol) if "s" in paths else static_s[node]
        loc[:, [sub_of[n] for n in nodes]] = compose_trs(T, R, S)
    with np.errstate(all="ignore"):  # an overflow to inf is caught by degenerate()
        world = _world(loc, sub_parents, sub_rrs)
    jw_ = world[:, jsub]
    bad = np.argwhere(degenerate(jw_))
    if len(bad):
        f0, j0 = bad[0]
        raise InputError(path, f"clip {clip!r} at {seconds[f0]:g} s: joint {jnames[j0] if len(jnames) > j0 else j0!r} "
                         f"has a world transform that {_BAD_XFORM}")
    b = len(jsub) + n_ghost
    out = np.empty((f, b, 4, 4))
    nb = len(jsub)
    par = np.asarray(jparents[:nb])
    out[:, :nb] = jw_
    kids = np.flatnonzero(par >= 0)
    if len(kids):
        out[:, kids] = np.linalg.solve(jw_[:, par[kids]], jw_[:, kids])
    for q in range(len(jsub), b):
        out[:, q] = rest[q]
    return out


def _interp_locals(frames, rate, jl, seconds):
    """Joint locals at ``seconds`` as UsdSkel interpolates the grid samples ``jl`` (lerp of
    translation and scale, slerp of rotation between the two neighbouring frames)."""
    t, q, s = decompose_trs(jl)
    x = np.asarray(seconds) * rate
    i = np.clip(np.searchsorted(frames, x, side="right") - 1, 0, len(frames) - 2) if len(frames) > 1 else np.zeros(len(x), int)
    if len(frames) == 1:
        return compose_trs(t[i], q[i], s[i])
    u = np.clip(x - frames[i], 0.0, 1.0)
    uu = np.broadcast_to(u[:, None], (len(u), jl.shape[1]))
    tt = t[i] + (t[i + 1] - t[i]) * uu[..., None]
    ss = s[i] + (s[i + 1] - s[i]) * uu[..., None]
    qq = slerp(q[i], q[i + 1], uu)
    return compose_trs(tt, qq, ss)


def _resampling_bound(frames, rate, jl, key_seconds, jl_keys, parents, bind, positions, ji, jw) -> float:
    """Upper bound, in skeleton units, of how far any vertex is from the source's pose at the
    source key times that fall between frames.

    Between two frames the asset interpolates each joint's TRS; the source interpolates between
    its own keys.  Both are smooth between their breakpoints, so the largest gap sits at a source
    key (for translations and scales, piecewise-linear, it is exactly there).  At each such key,
    a vertex skinned by joints ``j`` with weights summing to 1 is off by at most
    ``max_j |D_j p|`` with ``D_j`` the difference of the two skinning matrices; over the joint's
    vertices that is at most ``||D_j[:3, :3]||_2 * r_j + |D_j c_j|`` for a sphere ``(c_j, r_j)``
    around them.
    """
    asset = skel_transforms(_interp_locals(frames, rate, jl, key_seconds), parents)
    src = skel_transforms(jl_keys, parents)
    inv_bind = np.linalg.inv(bind)
    d = (asset - src) @ inv_bind  # (f, b, 4, 4)
    p = positions.astype(np.float64)
    bound = 0.0
    for j in range(len(bind)):
        rows = np.flatnonzero(np.any((ji == j) & (jw > 0), axis=1))
        if not len(rows):
            continue
        pts = p[rows]
        c = 0.5 * (pts.min(0) + pts.max(0))
        r = float(np.linalg.norm(pts - c, axis=1).max())
        dj = d[:, j]
        lin = np.linalg.norm(dj[:, :3, :3], ord=2, axis=(1, 2))
        off = np.linalg.norm(dj[:, :3, :3] @ c + dj[:, :3, 3], axis=1)
        bound = max(bound, float(np.max(lin * r + off)))
    return bound


def _weights_resampling_bound(frames, W, key_frames, W_keys, shapes, n, jl_keys, parents, bind) -> float:
    """Upper bound, in skeleton units, of how far the blend shapes move any vertex off the source's
    pose at the source key times that fall between frames (added to :func:`_resampling_bound`'s:
    the skinned point is linear in the shaped point, so the two errors add).

    The asset lerps each shape's weight between frames (``W`` (f, S) on ``frames``); the source
    is at ``W_keys`` (K, S) at ``key_frames`` (frame units).  A shape's displacement is piecewise
    linear in its weight (:class:`runtime.kernels.skin.Shapes`: knots at the in-betweens'
    weights, extrapolated past the ends), so a weight off by ``dw`` moves a vertex by at most
    ``dw`` times the shape's largest slope at that vertex, ``max |o_k+1 - o_k| / (w_k+1 - w_k)``
    over its consecutive knots; summed over shapes and carried by the skinning, whose linear
    part is at most the largest ``||M_j||`` of the source's pose at that key."""
    from ...model import kernel_shapes

    if not len(key_frames) or W is None or not W.shape[1]:
        return 0.0
    ks = kernel_shapes(shapes, n)  # n: the mesh's point count
    grid = np.stack([np.interp(key_frames, frames, W[:, s]) for s in range(W.shape[1])], axis=1)
    dw = np.abs(W_keys - grid)  # (K, S)
    slope = []
    for s in range(len(ks)):
        k, o = ks.knots[s], ks.knot_offsets[s]
        d = np.linalg.norm(np.diff(o, axis=0), axis=2) / np.diff(k)[:, None]  # (segments, m)
        slope.append(d.max(axis=0))
    skin = skel_transforms(jl_keys, parents) @ np.linalg.inv(bind)
    norm = np.linalg.norm(skin[..., :3, :3], ord=2, axis=(-2, -1)).max(axis=1)  # (K,)
    acc = np.zeros((len(key_frames), n))
    for s in range(len(ks)):
        if len(slope[s]):
            acc[:, ks.indices[s]] += dw[:, s:s + 1] * slope[s][None]
    return float((acc.max(axis=1, initial=0.0) * norm).max(initial=0.0))
