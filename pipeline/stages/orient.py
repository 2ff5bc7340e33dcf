"""``orient``: consistent winding per shell, closed shells facing outward.

A *shell* is a set of faces connected through manifold edges (edges used by exactly two faces).
Orientation propagates across those edges only: a non-manifold edge (3+ faces) is counted and
reported but joins nothing.  Within a shell, a breadth-first search from the shell's first face
gives every face a flip parity (the parity of "same direction" edges along the BFS tree).  Then:

* a **closed** shell (each of its edges used by exactly two of its faces) is flipped as a whole
  when its signed volume is negative, so it faces outward (counter-clockwise seen from outside);
* an **open** shell (or a closed one of zero volume) keeps the orientation of the majority of its
  original faces (the choice that flips fewer faces).

Edges still traversed twice in the same direction afterwards belong to non-orientable pieces
(a Möbius strip) and are reported.  Cost: a few integer sorts and scipy's BFS.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from colossus.pipeline.model import SkinnedMesh
from colossus.pipeline.stages import StageReport

#: A closed shell whose |signed volume| is below this fraction of the sum of its faces' absolute
#: volume terms has no usable inside; it falls back to the majority rule.
_FLAT_VOLUME_REL = 1e-9


def _bfs_parity(indptr, neighbors, odd, m):
    """Shells and flip parities by breadth-first search over the face graph (CSR).

    Parameters
    ----------
    indptr : (m + 1,) int64
    neighbors : (e,) int64, sorted within each face's row (scipy's csgraph may sort them, so
        the tree below is the one a BFS scanning them in that order builds)
    odd : (e,) uint8, 1 when the two faces traverse their shared edge in the same direction.
    m : int, face count.

    Returns
    -------
    shell : (m,) int64, shell id of each face (numbered in order of their lowest face).
    parity : (m,) uint8, flip relative to the shell's first face along the BFS tree (the same on
        any tree for an orientable shell).
    count : int, number of shells.

    scipy's csgraph does the searching: shells are the connected components; one BFS from an
    extra node linked to each shell's lowest face visits every shell as a BFS from that face
    would, scanning each face's neighbours in CSR order (so a face is reached through its first
    CSR entry from its BFS parent, whose ``odd`` is that tree edge's).  The parity, the XOR of
    ``odd`` along the tree path to the shell's first face, is accumulated by pointer doubling.
    """
    if m == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.uint8), 0
    graph = csr_matrix((np.ones(len(neighbors), np.int8), neighbors, indptr), shape=(m, m))
    count, label = connected_components(graph, directed=True, connection="weak")
    _, seeds = np.unique(label, return_index=True)  # lowest face of each component
    order = np.argsort(seeds, kind="stable")
    rank = np.empty(count, np.int64)
    rank[order] = np.arange(count)
    shell = rank[label]
    seeds = seeds[order]
    # the extra node m links to every seed
    ind2 = np.r_[neighbors, seeds]
    ptr2 = np.r_[indptr, indptr[-1] + len(seeds)]
    g2 = csr_matrix((np.ones(len(ind2), np.int8), ind2, ptr2), shape=(m + 1, m + 1))
    _, pred = breadth_first_order(g2, m, directed=True, return_predecessors=True)
    pred = pred[:m].astype(np.int64)
    pred[seeds] = seeds
    # odd of each tree edge (pred[f], f): the first CSR entry from pred[f] to f
    src = np.repeat(np.arange(m, dtype=np.int64), np.diff(indptr))
    key = src * m + neighbors
    ukey, first = np.unique(key, return_index=True)
    tree = pred != np.arange(m)
    bit = np.zeros(m, np.uint8)
    tk = pred[tree] * m + np.flatnonzero(tree)
    bit[tree] = odd[first[np.searchsorted(ukey, tk)]]
    # pointer doubling, O(m log depth): bit[f] is the XOR along the path from f up to (not
    # including) up[f]; a seed is its own up with bit 0, so the loop ends with every up a seed
    up = pred
    while not np.array_equal(up, up[up]):
        bit = bit ^ bit[up]
        up = up[up]
    return shell, bit, int(count)


def edge_table(triangles: np.ndarray, vertex_count: int):
    """Half-edges of a triangle mesh grouped by undirected edge.

    Parameters
    ----------
    triangles : (m, 3) int
    vertex_count : int

    Returns
    -------
    face : (h,) int64, face of each half-edge (degenerate half-edges ``a == b`` are left out),
        sorted so half-edges of one undirected edge are adjacent.
    forward : (h,) bool, the half-edge goes from the lower to the higher vertex index.
    run : (h,) int64, undirected edge id of each half-edge.
    run_start : (E,) int64, first half-edge of each undirected edge.
    run_len : (E,) int64, number of half-edges (faces) on each undirected edge.
    """
    t = np.asarray(triangles, dtype=np.int64)
    m = len(t)
    a = t.ravel()
    b = t[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(m, dtype=np.int64), 3)
    valid = a != b
    a, b, face = a[valid], b[valid], face[valid]
    lo = np.minimum(a, b)
    key = lo * np.int64(vertex_count) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    key, face, forward = key[order], face[order], (a < b)[order]
    if len(key):
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    else:
        starts = np.zeros(0, np.int64)
    run_len = np.diff(np.r_[starts, len(key)])
    run = np.repeat(np.arange(len(starts)), run_len)
    return face, forward, run, starts, run_len


def orient(mesh: SkinnedMesh) -> tuple[SkinnedMesh, StageReport]:
    """Make winding consistent per shell and closed shells outward-facing.

    Returns
    -------
    (SkinnedMesh, StageReport)
        Report counts: ``faces_flipped``, ``shells``, ``closed_shells``, ``open_shells``,
        ``nonmanifold_edges``, ``boundary_edges``, ``inconsistent_edges_remaining``.
    """
    tris = mesh.triangles.astype(np.int64)
    m = len(tris)
    face, forward, run, starts, run_len = edge_table(tris, mesh.vertex_count)

    # manifold edges: exactly two half-edges from two different faces
    two = run_len == 2
    s2 = starts[two]
    f1, f2 = face[s2], face[s2 + 1]
    distinct = f1 != f2
    f1, f2 = f1[distinct], f2[distinct]
    odd = (forward[s2] == forward[s2 + 1])[distinct].astype(np.uint8)

    src = np.concatenate([f1, f2])
    dst = np.concatenate([f2, f1])
    oo = np.concatenate([odd, odd])
    order = np.lexsort((dst, src))  # neighbours sorted within each face (see _bfs_parity)
    indptr = np.zeros(m + 1, np.int64)
    np.cumsum(np.bincount(src, minlength=m), out=indptr[1:])
    shell, parity, nshells = _bfs_parity(indptr, dst[order], oo[order], m)

    # closed shells: every edge of the shell used by exactly two faces of the shell
    open_shell = np.zeros(nshells, bool)
    he_len = run_len[run]
    open_shell[shell[face[he_len == 1]]] = True
    multi = he_len >= 3
    if multi.any():
        pair = np.stack([run[multi], shell[face[multi]]], axis=1)
        uniq, cnt = np.unique(pair, axis=0, return_counts=True)
        open_shell[uniq[cnt != 2, 1]] = True
    # an edge used twice by one face (a folded sliver) joins nothing and leaves its shell open
    open_shell[shell[face[s2[~distinct]]]] = True

    # signed volume of each shell with the propagated orientation
    p = mesh.positions.astype(np.float64)
    p -= 0.5 * (p.min(axis=0) + p.max(axis=0)) if len(p) else 0.0
    v0, v1, v2 = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    vol = np.einsum("ij,ij->i", v0, np.cross(v1, v2)) / 6.0
    sign = 1.0 - 2.0 * parity
    shell_vol = np.bincount(shell, weights=vol * sign, minlength=nshells)
    shell_abs = np.bincount(shell, weights=np.abs(vol), minlength=nshells)
    size = np.bincount(shell, minlength=nshells)
    npar = np.bincount(shell, weights=parity, minlength=nshells)
    usable = ~open_shell & (np.abs(shell_vol) > _FLAT_VOLUME_REL * shell_abs)
    flip_shell = np.where(usable, shell_vol < 0, (size - npar) < npar)

    flipped = (parity.astype(bool) ^ flip_shell[shell])
    new_tris = tris.copy()
    new_tris[flipped, 1] = tris[flipped, 2]
    new_tris[flipped, 2] = tris[flipped, 1]

    odd_after = odd.astype(bool) ^ flipped[f1] ^ flipped[f2]
    nclosed = int((~open_shell).sum())
    report = StageReport("orient")
    report.counts = {
        "faces_flipped": int(flipped.sum()),
        "shells": int(nshells),
        "closed_shells": nclosed,
        "open_shells": int(nshells - nclosed),
        "nonmanifold_edges": int((run_len >= 3).sum()),
        "boundary_edges": int((run_len == 1).sum()),
        "inconsistent_edges_remaining": int(odd_after.sum()),
    }
    if report.counts["nonmanifold_edges"]:
        report.warnings.append(
            f"{report.counts['nonmanifold_edges']} non-manifold edges (shared by 3 or more faces); "
            "orientation does not propagate across them")
    if report.counts["inconsistent_edges_remaining"]:
        report.warnings.append(
            f"{report.counts['inconsistent_edges_remaining']} edges still have inconsistent winding "
            "(non-orientable surface, e.g. a Moebius strip)")
    flat = int((~open_shell & ~usable).sum())
    if flat:
        report.warnings.append(f"{flat} closed shells have no volume; kept their majority orientation")
    return mesh.replace(triangles=new_tris.astype(np.int32)), report
