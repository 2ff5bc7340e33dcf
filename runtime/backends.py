"""The query backends of a :class:`runtime.collider.Pose`: one object per way of answering
``raycast`` and ``sphere_contacts`` (trimesh's ``ray/`` layout), chosen by name
(:func:`get_backend`, :data:`BACKENDS`) per collider or per query.

* :class:`PartsBackend` (``"parts"``, the default): provable part spheres, then chunk spheres,
  then exact tests on the triangles reached (:mod:`runtime.kernels.query`);
* :class:`BruteForceBackend` (``"brute"``): every triangle, no culling, the reference;
* :class:`TrimeshBackend` (``"trimesh"``): trimesh on the posed mesh, a baseline.

A backend reads the pose it is handed (its skinned points, culling and chunk spheres, scratch
buffers) and returns the records of :mod:`runtime.results`.
"""

from __future__ import annotations

import numpy as np

from .kernels import query as QK
from .results import SphereContacts

#: Above this many rays the parallel ray kernel is used.
PARALLEL_RAYS = 256


class PartsBackend:
    """Part spheres first, then exact tests on the triangles of the parts they pass."""

    name = "parts"

    def raycast(self, pose, origins, directions, max_distance):
        d = pose._data
        dist, tri, part, bary = _ray_buffers(len(origins))
        if len(origins) > PARALLEL_RAYS:
            pose._skin_all()
            pose._all_chunks()
            kern = QK._raycast_parallel
        else:
            kern = QK._raycast
        kern(origins, directions, max_distance, pose._points, d.triangles, pose.cull, d.faces,
             d.chunk_offsets, d.part_chunks, pose.chunk_spheres, pose._ready, pose._version,
             pose._lazy(), dist, tri, part, bary)
        return pose._ray_hits(origins, directions, dist, tri, part, bary)

    def sphere_contacts(self, pose, center, radius):
        d = pose._data
        s = pose._scratch()
        pose._stamp += 1
        n = QK._sphere_contacts(center, radius, pose._points, d.triangles, pose.cull, d.faces,
                               d.chunk_offsets, d.part_chunks, pose.chunk_spheres, pose._ready,
                               pose._version, pose._lazy(), d.faces_shared, s["mark"], pose._stamp,
                               *_contact_buffers(s))
        return _contacts(s, n)


class BruteForceBackend:
    """Every triangle, no culling: the reference the culled backend must always agree with
    (kernels of their own: game code never compiles them)."""

    name = "brute"

    def raycast(self, pose, origins, directions, max_distance):
        d = pose._data
        dist, tri, part, bary = _ray_buffers(len(origins))
        pose._skin_all()
        QK._raycast_all(origins, directions, max_distance, pose._points, d.triangles, dist, tri, part, bary)
        part = np.where(tri >= 0, d.face_part[np.maximum(tri, 0)], -1)
        return pose._ray_hits(origins, directions, dist, tri, part, bary)

    def sphere_contacts(self, pose, center, radius):
        s = pose._scratch()
        pose._skin_all()
        return _contacts(s, QK._sphere_contacts_all(center, radius, pose._points, pose._data.triangles,
                                                   *_contact_buffers(s)))


def _ray_buffers(R):
    """(distance (R,), triangle (R,), part (R,), barycentric (R, 3)) for a ray kernel to fill."""
    return np.empty(R), np.empty(R, dtype=np.int64), np.empty(R, dtype=np.int64), np.empty((R, 3))


def _contact_buffers(s):
    return s["tri"], s["point"], s["normal"], s["depth"], s["bary"]


def _contacts(s, n):
    """The first ``n`` contacts a kernel wrote into the pose's scratch ``s``, copied out."""
    return SphereContacts(s["tri"][:n].copy(), s["point"][:n].copy(), s["normal"][:n].copy(),
                          s["depth"][:n].copy(), s["bary"][:n].copy())


class TrimeshBackend:
    """trimesh on the posed mesh (embree when available), rebuilt per query: a baseline."""

    name = "trimesh"

    def _mesh(self, pose):
        import trimesh

        return trimesh.Trimesh(pose.points.astype(np.float64), pose._data.triangles, process=False)

    def raycast(self, pose, origins, directions, max_distance):
        m = self._mesh(pose)
        loc, ray, tri = m.ray.intersects_location(origins, directions, multiple_hits=True)
        R = len(origins)
        dist = np.full(R, np.inf)
        best = np.full(R, -1, dtype=np.int64)
        if len(ray):
            dd = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
            ok = (dd >= 0) & (dd <= max_distance)
            for r, t, f in zip(ray[ok], dd[ok], tri[ok]):
                if t < dist[r]:
                    dist[r], best[r] = t, f
        bary = np.zeros((R, 3))
        h = best >= 0
        if h.any():
            import trimesh

            pts = origins[h] + dist[h, None] * directions[h]
            bary[h] = trimesh.triangles.points_to_barycentric(m.triangles[best[h]], pts)
        part = np.where(h, pose._data.face_part[np.maximum(best, 0)], -1)
        return pose._ray_hits(origins, directions, dist, best, part, bary)

    def sphere_contacts(self, pose, center, radius):
        import trimesh

        m = self._mesh(pose)
        q = np.repeat(center[None], len(m.faces), 0)
        cp = trimesh.triangles.closest_point(m.triangles, q)
        dist = np.linalg.norm(cp - center, axis=1)
        idx = np.nonzero(dist <= radius)[0]
        nrm = center - cp[idx]
        ln = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.divide(nrm, ln, out=np.zeros_like(nrm), where=ln > 0)
        bary = trimesh.triangles.points_to_barycentric(m.triangles[idx], cp[idx]) if len(idx) else np.zeros((0, 3))
        return SphereContacts(idx.astype(np.int64), cp[idx], nrm, radius - dist[idx], bary)


BACKENDS = {b.name: b for b in (PartsBackend(), BruteForceBackend(), TrimeshBackend())}


def get_backend(backend):
    if backend is None or hasattr(backend, "raycast"):
        return backend
    try:
        return BACKENDS[backend]
    except KeyError:
        raise ValueError(f"unknown backend {backend!r}; one of {sorted(BACKENDS)}") from None
