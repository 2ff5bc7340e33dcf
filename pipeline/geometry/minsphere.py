"""Exact minimal enclosing sphere of a 3-D point set (numpy, and one numba kernel for the core-set loop).

Method (an iterative core-set scheme, after Gärtner's "Fast and robust smallest enclosing balls"
and the usual Welzl nested loop):

1. the core set starts as the extreme points of the input along 7 directions (14 points);
2. the exact minimal sphere of the core set is solved with Welzl's algorithm in its iterative
   nested-loop form on a deterministically shuffled copy (support sets of 1..4 points; collinear
   and coplanar support sets fall back to the smallest sphere enclosing them), in plain Python
   floats (IEEE float64): the core set stays small (tens of points), so this costs well under a
   millisecond;
3. one vectorised pass over all points finds, per chunk, the farthest point; the next core set
   is the sphere's boundary points plus those of them outside ``radius * (1 + 1e-9)`` (its
   sphere is strictly larger, so the loop ends), and we go back to 2;
4. when no point is outside, the returned radius is the exact (float64) largest distance from the
   centre to any input point, so containment holds even when the tolerance let a point slip.

Step 3 touches every point once per iteration (typically 2-5 iterations).  Step 1 is numpy
(BLAS); steps 2-4 are one numba kernel (:mod:`pipeline.geometry._minsphere_kernels`), ported
operation for operation from the plain-Python form kept here as :func:`_core_sphere_python`
(bit-identical: a test checks it).  Why: the spheres stage solves ~3,800 spheres of a few thousand
points on the 200,000-triangle benchmark, and interpreter overhead on the small core sets and the
per-call numpy passes made that ~14 s of the import.  The module once held 19 numba kernels
(about 30 s to compile on a cold cache); the loop kernel still costs ~3-5 s of CPU to compile
once per machine, so it runs only where the work pays for it (:data:`KERNEL_MIN`): small imports
keep the plain-Python form and compile nothing.

:func:`min_sphere` and :func:`min_spheres` validate their input; :func:`largest_min_sphere`
gives the largest of the per-set minimal radii exactly while solving only the sets that can be
the largest.  ``tests/references/naive.py`` holds a brute-force reference (every support set of up to 4
points).
"""

from __future__ import annotations

import math

import numpy as np

from colossus.pipeline.geometry import _minsphere_kernels as K

#: Initial core-set directions (both ends of each are used).
_DIRS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=np.float64)
#: Welzl's "point is outside" test: squared distance above ``r2 * (1 + _INSIDE_REL)``.
_INSIDE_REL = 1e-11
#: The core-set loop stops once every point lies within ``radius * (1 + CONTAIN_REL)``.
CONTAIN_REL = 1e-9
#: A triangle is collinear when ``|u x v|^2 <= _COLLINEAR * |u|^2 |v|^2`` (sin^2 of its angle).
_COLLINEAR = 1e-14
#: A tetrahedron is coplanar when ``|det(u, v, t)| <= _COPLANAR * |u| |v| |t|``.
_COPLANAR = 1e-10
#: Farthest-point chunks per pass (each may add one point to the core set).
_CHUNKS = 16
#: Rows per block of the distance pass (bounds the float64 temporaries to ~24 MB).
_BLOCK = 1 << 20
#: From this many points (summed over the sets of one call, or over the whole spheres stage: its
#: ``compiled`` argument) the core-set loop runs compiled.  The kernel costs ~3-5 s of CPU to
#: compile once per machine, the plain-Python form ~0.25 us per point: a demo-sized import (the
#: samples, the cold-start rows) never compiles it; a 200,000-triangle or a 1,000-frame character
#: (10-25 M points over its poses) does, and saves 10 s and more of every import after.
KERNEL_MIN = 8_000_000
#: Safety cap on core-set iterations (each adds at least one new point, so it is never reached
#: in practice; if it were, containment still holds, only minimality would suffer).
_MAX_ITER = 200


# -- support-set spheres (Python floats) ---------------------------------------------------------

def _d2(a, c):
    dx, dy, dz = a[0] - c[0], a[1] - c[1], a[2] - c[2]
    return dx * dx + dy * dy + dz * dz


def _ball2(a, b):
    c = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]))
    return c, max(_d2(a, c), _d2(b, c))


def _enclose3(a, b, c):
    """Smallest sphere of 3 (nearly) collinear points: the diameter ball of the farthest pair."""
    dab, dac, dbc = _d2(a, b), _d2(a, c), _d2(b, c)
    if dab >= dac and dab >= dbc:
        ctr, r2 = _ball2(a, b)
    elif dac >= dbc:
        ctr, r2 = _ball2(a, c)
    else:
        ctr, r2 = _ball2(b, c)
    return ctr, max(r2, _d2(a, ctr), _d2(b, ctr), _d2(c, ctr))


def _ball3(a, b, c):
    """Sphere through 3 points centred in their plane (their circumcircle)."""
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    wx, wy, wz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    ww = wx * wx + wy * wy + wz * wz
    if ww <= _COLLINEAR * uu * vv or ww == 0.0:
        return _enclose3(a, b, c)
    # centre = a + ((|u|^2 v - |v|^2 u) x w) / (2 |w|^2)
    px, py, pz = uu * vx - vv * ux, uu * vy - vv * uy, uu * vz - vv * uz
    s = 0.5 / ww
    ctr = (a[0] + (py * wz - pz * wy) * s, a[1] + (pz * wx - px * wz) * s, a[2] + (px * wy - py * wx) * s)
    return ctr, max(_d2(a, ctr), _d2(b, ctr), _d2(c, ctr))


def _enclose4(pts):
    """Smallest sphere of 4 (nearly) coplanar points: best pair or triple sphere holding all."""
    best = None
    for i in range(4):
        for j in range(i + 1, 4):
            cands = [_ball2(pts[i], pts[j])] + [_ball3(pts[i], pts[j], pts[k]) for k in range(j + 1, 4)]
            for ctr, r2 in cands:
                lim = r2 * (1.0 + 1e-9) + 1e-300
                if (best is None or r2 < best[1]) and all(_d2(q, ctr) <= lim for q in pts):
                    best = (ctr, r2)
    if best is None:  # numerically nothing fits: centroid and farthest corner
        ctr = tuple(0.25 * sum(q[a] for q in pts) for a in range(3))
        best = (ctr, max(_d2(q, ctr) for q in pts))
    return best


def _ball4(a, b, c, d):
    """Circumsphere of 4 points."""
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    tx, ty, tz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    vtx, vty, vtz = vy * tz - vz * ty, vz * tx - vx * tz, vx * ty - vy * tx  # v x t
    tux, tuy, tuz = ty * uz - tz * uy, tz * ux - tx * uz, tx * uy - ty * ux  # t x u
    uvx, uvy, uvz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx  # u x v
    det = ux * vtx + uy * vty + uz * vtz
    uu = ux * ux + uy * uy + uz * uz
    vv = vx * vx + vy * vy + vz * vz
    tt = tx * tx + ty * ty + tz * tz
    if abs(det) <= _COPLANAR * math.sqrt(uu * vv * tt) or det == 0.0:
        return _enclose4((a, b, c, d))
    s = 0.5 / det
    ctr = (a[0] + (uu * vtx + vv * tux + tt * uvx) * s, a[1] + (uu * vty + vv * tuy + tt * uvy) * s,
           a[2] + (uu * vtz + vv * tuz + tt * uvz) * s)
    return ctr, max(_d2(a, ctr), _d2(b, ctr), _d2(c, ctr), _d2(d, ctr))


def _welzl(S):
    """Minimal sphere of the points ``S`` (a list of float triples): Welzl's nested-loop form.

    Expected linear time for a random order (the caller shuffles).  Returns ``(centre, r2)``."""
    out = lambda q, ctr, r2: _d2(q, ctr) > r2 * (1.0 + _INSIDE_REL)  # noqa: E731
    ctr, r2 = S[0], 0.0
    for i in range(1, len(S)):
        if not out(S[i], ctr, r2):
            continue
        ctr, r2 = S[i], 0.0
        for j in range(i):
            if not out(S[j], ctr, r2):
                continue
            ctr, r2 = _ball2(S[i], S[j])
            for k in range(j):
                if not out(S[k], ctr, r2):
                    continue
                ctr, r2 = _ball3(S[i], S[j], S[k])
                for m in range(k):
                    if out(S[m], ctr, r2):
                        ctr, r2 = _ball4(S[i], S[j], S[k], S[m])
    return ctr, r2


# -- the core-set driver -------------------------------------------------------------------------

def _sqdist(P, c) -> np.ndarray:
    """(n,) float64 squared distances of the rows of ``P`` from ``c`` (blocked)."""
    out = np.empty(len(P))
    for s in range(0, len(P), _BLOCK):
        d = P[s:s + _BLOCK].T.astype(np.float64, order="C")  # a copy: modified in place below
        d -= np.asarray(c, dtype=np.float64)[:, None]
        d *= d
        np.add(np.add(d[0], d[1], out=out[s:s + _BLOCK]), d[2], out=out[s:s + _BLOCK])
    return out


def _compiled(points, compiled) -> bool:
    """Whether to run the kernel: ``compiled`` when given, else whether ``points`` holds at least
    :data:`KERNEL_MIN` points."""
    return bool(compiled) if compiled is not None else points.size >= 3 * KERNEL_MIN


def _core_sphere(P, hint=(), compiled=True) -> tuple[np.ndarray, float, list]:
    """Minimal sphere of ``P`` (n >= 1, 3) float32/float64, finite -> (centre (3,), radius, the
    core points on its boundary).  ``hint``: indices to add to the first core set (e.g. the
    boundary points of a similar set's sphere: fewer iterations).  One numba kernel
    (:func:`pipeline.geometry._minsphere_kernels._core_sphere`), bit-identical to
    :func:`_core_sphere_python` (which runs instead when ``compiled`` is false)."""
    if not compiled:
        return _core_sphere_python(P, hint)
    c, r, on = K._core_sphere(P if P.flags.c_contiguous else np.ascontiguousarray(P), np.array(hint, dtype=np.int64))
    return c, r, on.tolist()


def _first_core(P, hint=()) -> list:
    """Step 1: the extreme points of ``P`` along :data:`_DIRS`, after the ``hint`` indices
    (distinct, in that order)."""
    n = len(P)
    ext = []  # per block: the indices of its smallest and largest projections, and their values
    for s in range(0, n, _BLOCK):
        proj = _DIRS @ np.ascontiguousarray(P[s:s + _BLOCK].T, dtype=np.float64)  # (7, block): BLAS
        lo, hi = proj.argmin(1), proj.argmax(1)
        ext.append((lo + s, hi + s, proj[np.arange(7), lo], proj[np.arange(7), hi]))
    lo_i, hi_i, lo_v, hi_v = (np.array([e[k] for e in ext]) for k in range(4))
    k = np.arange(7)
    return list(dict.fromkeys(list(hint) + np.r_[lo_i[lo_v.argmin(0), k], hi_i[hi_v.argmax(0), k]].tolist()))


def _core_sphere_python(P, hint=()) -> tuple[np.ndarray, float, list]:
    """:func:`_core_sphere` in plain Python and numpy, the form the kernel was ported from (kept
    as its reference: ``tests/pipeline/test_stages_geometry.py`` checks they agree bit for bit)."""
    n = len(P)
    core = _first_core(P, hint)
    o = P[core[0]].astype(np.float64)
    nch = min(_CHUNKS, n)
    bounds = [c * n // nch for c in range(nch + 1)]
    seed = 12345
    ctr, r2, maxd2 = o, 0.0, 0.0
    for _ in range(_MAX_ITER):
        # exact sphere of the core set, relative to the first core point for precision
        S = [tuple(x) for x in (P[core].astype(np.float64) - o).tolist()]
        for s in range(len(S) - 1, 0, -1):  # deterministic Fisher-Yates shuffle (LCG)
            seed = (seed * 1103515245 + 12345) % 2147483648
            t = seed % (s + 1)
            S[s], S[t] = S[t], S[s]
        c, r2 = _welzl(S)
        ctr = np.array(c) + o
        d2 = _sqdist(P, ctr)
        far = [bounds[c] + int(np.argmax(d2[bounds[c]:bounds[c + 1]])) for c in range(nch)]
        maxd2 = float(d2[far].max())
        lim = r2 * (1.0 + CONTAIN_REL) * (1.0 + CONTAIN_REL)
        if maxd2 <= lim:
            break
        on = _boundary(P, core, o, c, r2)
        known = set(on)
        added = [i for i in far if d2[i] > lim and i not in known]
        if not added:  # numerically stuck: the radius below still covers every point
            break
        # the next core: this sphere's boundary points and the points outside it (the sphere of
        # that set is strictly larger, so the loop ends; and the core stays a few points)
        core = on + list(dict.fromkeys(added))
    return ctr, math.sqrt(max(r2, maxd2)), _boundary(P, core, o, c, r2)


def _boundary(P, core, o, c, r2) -> list:
    """The core points on the boundary of the sphere ``(c, r2)`` (relative to ``o``)."""
    return [i for i in core if _d2(P[i].astype(np.float64) - o, c) >= r2 * (1.0 - 1e-7)]


# -- public wrappers -----------------------------------------------------------------------------

def _as_points(points, ndim: int, what: str) -> np.ndarray:
    p = np.asarray(points)
    if p.dtype != np.float32:
        p = p.astype(np.float64, copy=False)
    want = "(n, 3)" if ndim == 2 else "(F, n, 3)"
    if p.ndim != ndim or p.shape[-1] != 3:
        raise ValueError(f"{what}: expected shape {want}, got {p.shape}")
    if p.shape[-2] == 0:
        raise ValueError(f"{what}: expected at least one point, got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{what}: expected finite coordinates, got NaN or inf")
    return p


def min_sphere(points: np.ndarray, compiled: bool | None = None) -> tuple[np.ndarray, float]:
    """Minimal enclosing sphere of a point set.

    Parameters
    ----------
    points : (n, 3) float32 or float64, n >= 1, finite.
    compiled : run the numba kernel (True) or the plain-Python form (False), bit-identical
        results; default: the kernel from :data:`KERNEL_MIN` points.

    Returns
    -------
    center : (3,) float64
    radius : float
        The largest float64 distance from ``center`` to a point, so every point is contained;
        it exceeds the exact minimal radius by at most about ``1e-9`` relative.
    """
    p = _as_points(points, 2, "min_sphere points")
    c, r, _ = _core_sphere(p, (), _compiled(p, compiled))
    return c, float(r)


def min_spheres(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimal enclosing sphere of each of ``F`` point sets of the same size (e.g. frames).

    Parameters
    ----------
    points : (F, n, 3) float32 or float64, n >= 1, finite.

    Returns
    -------
    centers : (F, 3) float64
    radii : (F,) float64
    """
    p = _as_points(points, 3, "min_spheres points")
    centers = np.zeros((len(p), 3))
    radii = np.zeros(len(p))
    compiled = _compiled(p, None)
    for f in range(len(p)):
        centers[f], radii[f], _ = _core_sphere(p[f], (), compiled)
    return centers, radii


def largest_min_sphere(points: np.ndarray, center=None, rel: float = 0.0, compiled: bool | None = None) -> float:
    """The largest of the minimal enclosing radii of ``F`` point sets, ``max_f min_sphere(points[f])``
    (exactly, or at most ``rel`` relative below it), solving only the sets that can be the
    largest.

    Each set's minimal radius is at most its farthest distance from any centre (the ball around
    that centre holding the set is no smaller than the minimal one): from its bounding-box centre,
    or from ``center`` (3,) when given (e.g. the minimal sphere of all the sets together, which
    for the poses of a near-rigid part is close to each pose's own).  The sets are solved in
    decreasing order of that bound until the next bound cannot beat the largest radius found by
    more than ``rel`` (with ``rel > 0`` the many poses of a rigid part, whose minimal spheres
    differ only by rounding, are solved once).

    Parameters
    ----------
    points : (F, n, 3) float32 or float64, F >= 1, n >= 1, finite.
    center : (3,), optional
    rel : float >= 0
    compiled : as :func:`min_sphere`'s (default: the kernel from :data:`KERNEL_MIN` points in all).
    """
    p = _as_points(points, 3, "largest_min_sphere points")
    compiled = _compiled(p, compiled)
    mid = 0.5 * (p.min(1).astype(np.float64) + p.max(1).astype(np.float64))
    p = p if p.flags.c_contiguous else np.ascontiguousarray(p)
    far2 = K._farthest2 if compiled else (lambda q, c: _sqdist(q, c).max())  # the same float64 values
    upper = np.array([far2(p[f], mid[f]) for f in range(len(p))])
    if center is not None:
        c = np.asarray(center, dtype=np.float64).reshape(3)
        upper = np.minimum(upper, [far2(p[f], c) for f in range(len(p))])
    upper = np.sqrt(upper) * (1 + 1e-12)
    best = -1.0
    hint = []
    for f in np.argsort(-upper, kind="stable"):
        if upper[f] <= best * (1.0 + rel):
            break
        _, r, hint = _core_sphere(p[f], hint, compiled)  # the sets are alike: start from the last boundary
        best = max(best, r)
    return best
