"""COL2xx mesh: the collision triangles, in the bind pose."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from colossus.runtime import schema

from .. import tolerances as tol
from ..registry import hit, rule


def _edges(tris):
    """Directed edges (3m, 2) in face order: face f owns rows 3f, 3f+1, 3f+2."""
    return np.stack([tris, np.roll(tris, -1, axis=1)], -1).reshape(-1, 2).astype(np.int64)


@rule("COL201", "triangles-only", "error", "The collider is triangles only.", needs=("mesh_raw",))
def triangles_only(asset, ctx):
    """What: every entry of `faceVertexCounts` is 3.
    Why: the runtime ray-casts and contacts triangles; a polygon would be silently skipped or
    triangulated differently by each consumer.
    Example: a quad (`faceVertexCounts = [4]`) left over from the source mesh."""
    bad = np.nonzero(asset.face_counts != 3)[0]
    if len(bad):
        f = int(bad[0])
        yield hit(f"{len(bad)} of {len(asset.face_counts)} faces are not triangles; face {f} has "
                  f"{int(asset.face_counts[f])} vertices", face=f, count=len(bad))


@rule("COL202", "vertex-indices", "error", "Face vertex indices point at existing points.", needs=("mesh_raw",))
def vertex_indices(asset, ctx):
    """What: every entry of `faceVertexIndices` is in [0, number of points).
    Why: an out-of-range index reads garbage memory at run time.
    Example: `faceVertexIndices` mentioning point 402 on a 402-point mesh."""
    i = asset.face_indices
    bad = np.nonzero((i < 0) | (i >= asset.n))[0]
    if len(bad):
        face = int(np.searchsorted(np.cumsum(asset.face_counts), bad[0], side="right"))
        yield hit(f"{len(bad)} face vertex indices out of range [0, {asset.n}), first {int(i[bad[0]])}",
                  face=face, count=len(bad))


@rule("COL203", "finite-points", "error", "No point is NaN or infinite.", needs=("mesh_raw",))
def finite_points(asset, ctx):
    """What: every coordinate of `points` (and of `geomBindTransform`) is finite.
    Why: one NaN vertex poisons every ray and contact test that touches its triangles.
    Example: a vertex at `(nan, 0, 0)` from a division by a zero-length normal in the exporter."""
    bad = np.nonzero(~np.all(np.isfinite(asset.points), axis=1))[0]
    if len(bad):
        yield hit(f"{len(bad)} points are NaN or infinite, first vertex {int(bad[0])}",
                  vertex=int(bad[0]), count=len(bad))
    if not np.all(np.isfinite(asset.geom_bind)):
        yield hit("primvars:skel:geomBindTransform is not finite")


@rule("COL204", "zero-area", "error", "No triangle has zero area.", needs=("mesh",))
def zero_area(asset, ctx):
    """What: every triangle's bind-pose area exceeds (1e-7 x model size)^2 (repeated vertex
    indices included).
    Why: a degenerate triangle has no normal: contact normals and winding checks are undefined.
    Example: a triangle `(5, 5, 9)`, or three collinear points."""
    # the one test, shared with the importer's `degenerate` stage (runtime.schema.zero_area_faces)
    linear = (asset.skel_world @ asset.geom_bind)[:3, :3]
    bad = np.nonzero(schema.zero_area_faces(asset.points, asset.tris, linear, asset.model_size,
                                            tol.ZERO_AREA_RELATIVE))[0]
    if len(bad):
        yield hit(f"{len(bad)} triangles have zero area, first face {int(bad[0])}", face=int(bad[0]), count=len(bad))


@rule("COL205", "unreferenced-vertices", "warning", "Every point is used by a triangle.", needs=("mesh",))
def unreferenced_vertices(asset, ctx):
    """What: every point appears in `faceVertexIndices`.
    Why: unused points are skinned every frame for nothing and confuse vertex-indexed reports.
    Example: the cap centre vertex left behind after the cap faces were deleted."""
    used = np.zeros(asset.n, bool)
    used[asset.tris.ravel()] = True
    bad = np.nonzero(~used)[0]
    if len(bad):
        yield hit(f"{len(bad)} points are used by no triangle, first vertex {int(bad[0])}",
                  vertex=int(bad[0]), count=len(bad))


def _grid(x):
    """Snap finite floats to integer grid keys (int64), clamped so that absurd coordinates of a
    corrupt asset do not overflow the cast."""
    return np.round(np.clip(x, -2.0**62, 2.0**62)).astype(np.int64)


@rule("COL206", "unwelded-duplicates", "warning",
      "No two vertices share a position and skin influences (they should have been welded).", needs=("mesh",))
def unwelded_duplicates(asset, ctx):
    """What: no two points lie within 1e-6 x model size of each other (snapped to that grid) while
    also having the same skin influences.  Vertices at one position with different influences
    are genuinely different and allowed.
    Why: unwelded seams split the surface into shells: rays slip through the crack and the
    winding and volume checks see open shells.
    Example: a UV seam exported as duplicated vertices."""
    p = asset.bind_points
    ok = np.all(np.isfinite(p), axis=1)
    keys = [_grid(p[ok] / (tol.WELD_RELATIVE * asset.model_size))]
    if asset.jidx is not None and len(asset.jidx) == asset.n:
        w = np.nan_to_num(asset.jw[ok].astype(np.float64))
        keys += [np.where(w > 0, asset.jidx[ok], -1), _grid(w / 1e-4)]
    key = np.concatenate(keys, axis=1)
    idx = np.nonzero(ok)[0]
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    dup = counts[inv.ravel()] > 1
    if np.any(dup):
        first = idx[np.argmax(dup)]
        yield hit(f"{int(dup.sum())} vertices duplicate another vertex's position and influences, "
                  f"first vertex {int(first)}", vertex=int(first), count=int(dup.sum()))


def _edge_table(tris):
    """(undirected unique edges (e, 2), face count per edge (e,), edge id per directed edge (3m,))."""
    d = _edges(tris)
    u = np.sort(d, axis=1)
    und, inv, cnt = np.unique(u, axis=0, return_inverse=True, return_counts=True)
    return und, cnt, inv.ravel(), d


@rule("COL207", "non-manifold-edges", "warning", "No edge is shared by more than two triangles.", needs=("mesh",))
def non_manifold_edges(asset, ctx):
    """What: every edge belongs to at most two triangles.
    Why: "inside" and "outside" are undefined around a non-manifold edge, so contact normals and
    the volume test are unreliable there.
    Example: three fins sharing one edge."""
    und, cnt, _, _ = _edge_table(asset.tris)
    bad = np.nonzero(cnt > 2)[0]
    if len(bad):
        a, b = und[bad[0]]
        yield hit(f"{len(bad)} edges are shared by more than two triangles, first edge ({a}, {b}) by "
                  f"{int(cnt[bad[0]])}", vertex=int(a), count=len(bad))


@rule("COL208", "inconsistent-winding", "error",
      "Neighbouring triangles wind the same way (each shared edge runs opposite in the two).", needs=("mesh",))
def inconsistent_winding(asset, ctx):
    """What: across every edge shared by exactly two triangles, the two use it in opposite
    directions.
    Why: a flipped triangle has an inward normal: contacts on it push the player into the mesh.
    Example: one triangle of a tube written as `(a, b, c)` instead of `(a, c, b)`."""
    und, cnt, eid, d = _edge_table(asset.tris)
    manifold = cnt[eid] == 2
    key = d[:, 0] * max(asset.n, 1) + d[:, 1]
    k = key[manifold]
    uk, c = np.unique(k, return_counts=True)
    bad = uk[c > 1]
    if len(bad):
        rows = np.nonzero(manifold)[0][np.isin(k, bad)]
        face = int(rows.max() // 3)
        yield hit(f"{len(bad)} shared edges run the same direction in both triangles; e.g. face {face} "
                  f"disagrees with its neighbour", face=face, count=len(bad))


@rule("COL209", "inside-out", "error", "Closed shells enclose positive volume (outward-facing).", needs=("mesh",))
def inside_out(asset, ctx):
    """What: every closed, consistently wound shell (connected set of triangles whose edges are
    each shared by exactly two of them) has positive signed volume in the bind pose
    (`orientation` and a mirroring geomBindTransform taken into account).
    Why: an inside-out collider pushes the player inwards on every contact.
    Example: every triangle of the tube reversed, or `orientation = "leftHanded"` on CCW data."""
    tris = asset.tris
    n = asset.n
    if len(tris) == 0:
        return
    d = _edges(tris)
    g = coo_matrix((np.ones(len(d)), (d[:, 0], d[:, 1])), shape=(n, n))
    _, label = connected_components(g, directed=False)
    shell = label[tris[:, 0]]
    und, cnt, eid, _ = _edge_table(tris)
    closed_edge = (cnt[eid] == 2).reshape(-1, 3).all(1)
    s_ids, s_inv = np.unique(shell, return_inverse=True)
    closed = np.bincount(s_inv, weights=~closed_edge, minlength=len(s_ids)) == 0
    p = asset.bind_points[tris]
    vol6 = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2]))
    if asset.orientation == "leftHanded":
        vol6 = -vol6
    vol = np.bincount(s_inv, weights=vol6, minlength=len(s_ids)) / 6
    bad = np.nonzero(closed & (vol < 0))[0]
    for s in bad[:20]:
        face = int(np.argmax(s_inv == s))
        yield hit(f"closed shell of {int((s_inv == s).sum())} triangles has negative volume {vol[s]:.4g} "
                  f"(inside out)", face=face, sort_key=-vol[s])
