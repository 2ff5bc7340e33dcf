"""Pictures of a collider asset: the collision mesh and every part's sphere, at the bind pose or
any time of any clip (``colossus render``, and the pictures of ``validate --format html``).

Geometry comes from the same code as the frame proof (:mod:`validators.frameproof`: UsdSkel
joint transforms, ``skinning_transforms``, ``skin_frames``, ``world_spheres``) and a vertex is
outside its sphere by the proof's own tolerance, so a part drawn red is a part the proof fails.

Drawing is offscreen VTK through pyvista.  Without an X display (``$DISPLAY`` unset) on Linux,
VTK is pointed at its EGL window (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``; Mesa's
software EGL is enough, no GPU or X server needed) when ``libEGL`` is present.

Public functions
----------------
source_mesh(asset, path) -> SourceMesh
pose_at(asset, clip=None, time=None, source=None) -> Pose
poses(asset, clip, times, source=None) -> list of Pose
slack_series(asset, clip) -> (times (f,), slack (f, P))
part_colors(P) -> (P, 3) float in [0, 1]
render_image(asset, pose, size=(800, 600)) -> (H, W, 3) uint8
render_png(asset, out, clip=None, time=None, size=(800, 600), source=None)
render_gif(asset, out, clip=None, size=(480, 360), max_frames=60, source=None)

``source`` (:func:`source_mesh`): the full mesh a collision proxy was made from, imported from its
export with the asset's own settings up to ``bind`` and posed by the asset's own joints, drawn
faintly behind the collider so a person sees the fit.
"""

from __future__ import annotations

import colorsys
import ctypes.util
import os
import sys
from dataclasses import dataclass

import numpy as np

from colossus.pipeline.tempfiles import write_atomic
from colossus.runtime.errors import ColossusError

from colossus.validators import frameproof as fp
from colossus.validators import tolerances as tol

#: Colour of a failing part, its sphere, and of the markers on its offending vertices.
FAIL_RGB = (0.95, 0.04, 0.04)
MARK_RGB = (1.0, 0.85, 0.0)
BACKGROUND = (0.97, 0.97, 0.96)
SPHERE_OPACITY = 0.18
#: The full mesh behind a proxy (``--source``): colour and opacity.
SOURCE_RGB = (0.35, 0.35, 0.4)
SOURCE_OPACITY = 0.3


class RenderError(ColossusError):
    """The asset cannot be drawn (what it lacks), or the clip/time asked for does not exist.
    ``str()`` is one line."""


# ------------------------------------------------------------------------------ geometry
@dataclass
class Pose:
    """One drawable pose.

    Attributes
    ----------
    label : str                 e.g. ``"bind pose"`` or ``"walk  t=12  frame 12/49"``
    clip : str or None, time : float or None
    points : (n, 3) float32     skinned vertices, stage space
    centers : (P, 3) float64, radii : (P,) float64   part spheres, stage space
    excess : (P,) float64       farthest vertex distance minus radius (> tolerance: failing)
    failing : (P,) bool
    outside : (m,) int          vertices outside a sphere of a part they belong to
    source_points : (n_s, 3) float32 or None   the full mesh (``source``) at the same pose
    """

    label: str
    clip: str | None
    time: float | None
    points: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    excess: np.ndarray
    failing: np.ndarray
    outside: np.ndarray
    source_points: np.ndarray | None = None


@dataclass
class SourceMesh:
    """The full skinned mesh an asset (a collision proxy) was made from, in the asset's joints.

    path : str; positions : (n, 3) float32 mesh space; triangles : (m, 3) int64;
    joint_indices : (n, k) int32 into the asset's joints; joint_weights : (n, k) float32;
    inv_bind : (b, 4, 4) float64 (asset joint order); geom_bind : (4, 4) float64
    """

    path: str
    positions: np.ndarray
    triangles: np.ndarray
    joint_indices: np.ndarray
    joint_weights: np.ndarray
    inv_bind: np.ndarray
    geom_bind: np.ndarray

    def points(self, asset, skel) -> np.ndarray:
        """``(f, n, 3)`` float32 stage-space points for ``(f, b, 4, 4)`` skeleton-space joint
        transforms of the asset."""
        sk = fp.skinning_transforms(skel, self.inv_bind, self.geom_bind, asset.skel_world)
        return fp.skin_frames(self.positions, self.joint_indices, self.joint_weights, sk)


def source_mesh(asset, path) -> SourceMesh:
    """Import ``path`` (the export the asset was made from, or a full-mesh asset) with the asset's
    own import settings (its provenance; no simplification) up to ``bind``, its joints matched
    to the asset's by name.  Raises :class:`RenderError` when its skeleton lacks an influencing
    joint of the asset's, and the import's own errors for an unreadable file."""
    from pxr import UsdSkel

    from colossus.pipeline.run import build_collider, settings_from_provenance
    from colossus.runtime import schema

    prov = asset.mesh.GetCustomDataByKey(schema.PROVENANCE_KEY) if asset.mesh is not None else None
    settings = settings_from_provenance(dict((prov if isinstance(prov, dict) else {}).get("settings") or {}))
    settings.target_faces = settings.max_deviation = None
    mesh, _ = build_collider(os.fspath(path), settings, stop_after="bind")
    names = UsdSkel.Skeleton(asset.skeleton).GetJointNamesAttr().Get()
    names = [str(n) for n in names] if names else [j.rsplit("/", 1)[-1] for j in asset.joints]
    index = {n: i for i, n in enumerate(names)}
    used = np.unique(mesh.joint_indices[mesh.joint_weights > 0])
    missing = [mesh.joint_names[j] for j in used if mesh.joint_names[j] not in index]
    if missing:
        raise RenderError(f"{path}: its skeleton does not match {asset.path}'s (no joint {missing[0]!r} there)")
    to_asset = np.array([index.get(n, 0) for n in mesh.joint_names], dtype=np.int32)
    inv_bind = np.linalg.inv(asset.bind)
    return SourceMesh(os.fspath(path), mesh.positions, mesh.triangles.astype(np.int64),
                      to_asset[mesh.joint_indices], mesh.joint_weights, inv_bind, mesh.geom_bind)


def check_drawable(asset) -> None:
    """Raise :class:`RenderError` unless the asset has what drawing needs (a triangle mesh, a
    skeleton, usable skin, parts with finite spheres)."""
    ok, why = asset.ready("spheres")
    if not ok:
        raise RenderError(f"{asset.path}: cannot draw it: {why}")


def _find_clip(asset, clip):
    for c in asset.clips:
        if c.name == clip:
            return c
    names = ", ".join(c.name for c in asset.clips) or "none"
    raise RenderError(f"no clip {clip!r} (clips: {names})")


def _poses_from_skel(asset, skel, labels, clip, times, source=None) -> list:
    """Poses for ``(f, b, 4, 4)`` skeleton-space joint transforms (and ``source`` posed alike)."""
    joint_world = asset.skel_world @ skel
    sk = fp.skinning_transforms(skel, asset.inv_bind, asset.geom_bind, asset.skel_world)
    pts = fp.skin_frames(asset.points, asset.jidx, asset.jw, sk)
    wc, wr, _ = fp.world_spheres(joint_world, asset.part_joint_ids, asset.part_centers, asset.part_radii)
    poff, pverts = asset.part_vertices
    P = len(asset.part_joints)
    pid = np.repeat(np.arange(P), np.diff(poff))
    spts = source.points(asset, skel) if source is not None else None
    out = []
    for i in range(len(skel)):
        d = np.linalg.norm(pts[i, pverts].astype(np.float64) - wc[i, pid], axis=1)
        limit = tol.CONTAIN_RELATIVE * asset.model_size + tol.CONTAIN_RADIUS * wr[i]
        over = d - wr[i, pid]
        bad = over > limit[pid]
        excess = np.full(P, -np.inf)
        np.maximum.at(excess, pid, over)
        failing = np.zeros(P, bool)
        failing[pid[bad]] = True
        out.append(Pose(labels[i], clip, None if times is None else float(times[i]), pts[i], wc[i], wr[i],
                        excess, failing, np.unique(pverts[bad]), None if spts is None else spts[i]))
    return out


def pose_at(asset, clip: str | None = None, time: float | None = None, source: SourceMesh | None = None) -> Pose:
    """The bind pose (``clip=None``) or ``clip`` at ``time`` (default its first frame; any time,
    interpolated by ``UsdSkel.AnimQuery`` between samples)."""
    check_drawable(asset)
    if clip is None:
        return _poses_from_skel(asset, asset.bind[None], ["bind pose"], None, None, source)[0]
    c = _find_clip(asset, clip)
    if len(c.times) == 0:
        raise RenderError(f"clip {clip!r} has no frames")
    t = float(c.times[0]) if time is None else float(time)
    return poses(asset, clip, [t], source)[0]


def poses(asset, clip: str, times, source: SourceMesh | None = None) -> list:
    """Poses of ``clip`` at each of ``times`` (one batch through the skinning kernel)."""
    check_drawable(asset)
    c = _find_clip(asset, clip)
    times = np.asarray(times, dtype=np.float64)
    skel = asset.skel_transforms(asset.anim_local(c, times))
    labels = []
    for t in times:
        k = int(np.searchsorted(c.times, t + tol.TIME_CODE_EPS) - 1)
        on = k >= 0 and abs(c.times[k] - t) <= tol.TIME_CODE_EPS
        frame = f"frame {k}/{len(c.times)}" if on else f"after frame {max(k, 0)}"
        labels.append(f"{c.name}  t={t:g}  {frame}")
    return _poses_from_skel(asset, skel, labels, c.name, times, source)


def slack_series(asset, clip: str):
    """Each part's sphere slack on every frame of ``clip``: world radius minus the distance of the
    part's farthest skinned vertex (stage units; negative = a vertex is outside).

    Returns ``(times (f,) float64, slack (f, P) float64)``.
    """
    check_drawable(asset)
    c = _find_clip(asset, clip)
    poff, pverts = asset.part_vertices
    times = c.times
    slack = np.empty((len(times), len(asset.part_joints)))
    chunk = fp.chunk_size(len(asset.joints), len(asset.part_joints))
    for lo in range(0, len(times), chunk):
        t = times[lo:lo + chunk]
        skel = asset.skel_transforms(asset.anim_local(c, t))
        sk = fp.skinning_transforms(skel, asset.inv_bind, asset.geom_bind, asset.skel_world)
        wc, wr, _ = fp.world_spheres(asset.skel_world @ skel, asset.part_joint_ids, asset.part_centers,
                                     asset.part_radii)
        d, _ = fp.part_farthest(asset.points, asset.jidx, asset.jw, sk, poff, pverts, wc)
        slack[lo:lo + len(t)] = wr - d
    return times, slack


def part_colors(P: int) -> np.ndarray:
    """``(P, 3)`` distinct soft colours, none of them red (red means failing)."""
    h = (np.arange(P) * 0.618034) % 1.0
    hue = 0.11 + h * 0.78  # 40 .. 320 degrees: keeps clear of red
    return np.array([colorsys.hsv_to_rgb(x, 0.55, 0.92) for x in hue]).reshape(-1, 3)


# ------------------------------------------------------------------------------- drawing
def offscreen_pyvista():
    """pyvista set up to draw offscreen, VTK's warnings silenced: the one set-up every picture of
    the project uses (``render``, ``play``, the HTML report).  On Linux without a display it asks VTK
    for an EGL window where EGL exists."""
    if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and ctypes.util.find_library("EGL"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger, vtkObject

    pv.OFF_SCREEN = True
    vtkObject.GlobalWarningDisplayOff()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    return pv


def parse_size(text: str):
    """``"WxH"`` -> ``(W, H)``; raises ValueError naming the expected form."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"expected WxH (e.g. 800x600), got {text!r}") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise ValueError(f"each side must be 16..4096 pixels, got {text!r}")
    return w, h


def _view_direction(points, up) -> np.ndarray:
    """Unit vector from the model towards the camera: 35 degrees round from square-on to the
    side of the longest horizontal extent (principal axis of the points), 25 degrees up."""
    p = np.asarray(points, dtype=np.float64)
    flat = p - np.outer(p @ up, up)
    flat = flat - flat.mean(0)
    axis = np.linalg.svd(flat, full_matrices=False)[2][0] if len(flat) > 2 else np.cross(up, [1.0, 0, 0])
    side = np.cross(up, axis)
    if np.linalg.norm(side) < 1e-9:
        side = np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    axis = np.cross(side, up)
    a, e = np.radians(35.0), np.radians(25.0)
    d = np.cos(e) * (np.cos(a) * side + np.sin(a) * axis) + np.sin(e) * up
    return d / np.linalg.norm(d)


class Renderer:
    """One offscreen window drawing successive poses of one asset with a fixed camera.

    Parameters
    ----------
    asset : LoadedAsset (``check_drawable``)
    size : (W, H)
    fit : list of Pose      the camera is fitted to all of them (a whole clip: no jumping)
    source : SourceMesh, optional   the full mesh, drawn faint behind (the poses carry its points)
    """

    def __init__(self, asset, size=(800, 600), fit=(), source=None):
        from pxr import UsdGeom

        pv = offscreen_pyvista()
        self.pv = pv
        self.asset = asset
        self.size = tuple(size)
        P = len(asset.part_joints)
        self.colors = part_colors(P)
        tris = asset.tris
        # each face drawn in the colour of the lowest-numbered part that has it
        self.face_part = np.full(len(tris), -1, dtype=np.int64)
        poff = asset.part_offsets
        for p in range(P - 1, -1, -1):
            self.face_part[asset.part_faces[poff[p]:poff[p + 1]]] = p
        self.part_faces = [asset.part_faces[poff[p]:poff[p + 1]] for p in range(P)]
        base = np.vstack([self.colors * 0.9 + 0.1, [[0.7, 0.7, 0.7]]])
        self.base_rgb = (base[self.face_part] * 255).astype(np.uint8)

        pl = pv.Plotter(off_screen=True, window_size=list(self.size), lighting="light_kit")
        pl.set_background(BACKGROUND)
        faces = np.hstack([np.full((len(tris), 1), 3, dtype=np.int64), tris]).ravel()
        self.mesh = pv.PolyData(asset.bind_points.astype(np.float32), faces=faces)
        self.mesh.cell_data["rgb"] = self.base_rgb.copy()
        pl.add_mesh(self.mesh, scalars="rgb", rgb=True, show_scalar_bar=False, ambient=0.2,
                    diffuse=0.85, specular=0.2, render=False)
        self.source = None
        if source is not None:
            sf = np.hstack([np.full((len(source.triangles), 1), 3, dtype=np.int64), source.triangles]).ravel()
            first = next((p.source_points for p in fit if p is not None and p.source_points is not None), None)
            self.source = pv.PolyData(first if first is not None else source.positions.astype(np.float32), faces=sf)
            pl.add_mesh(self.source, color=SOURCE_RGB, opacity=SOURCE_OPACITY, ambient=0.3, diffuse=0.6,
                        show_scalar_bar=False, render=False)
        unit = pv.Sphere(radius=1.0, theta_resolution=32, phi_resolution=20)
        self.spheres = []
        for p in range(P):
            a = pl.add_mesh(unit, color=self.colors[p], opacity=SPHERE_OPACITY, smooth_shading=True,
                            show_scalar_bar=False, render=False)
            self.spheres.append(a)
        self.marks_poly = pv.PolyData(np.zeros((1, 3), np.float32))
        self.marks = pl.add_mesh(self.marks_poly, color=MARK_RGB, point_size=max(5, self.size[0] // 110),
                                 render_points_as_spheres=True, render=False)
        self.marks.SetVisibility(False)
        self.text = pl.add_text("", position=(6, self.size[1] - 4), font_size=max(6, min(10, self.size[0] // 64)),
                                color="black")
        self.text.GetTextProperty().SetVerticalJustificationToTop()
        self.plotter = pl

        # camera: parallel projection, a three-quarter view from above the side of the model's
        # longest horizontal extent, fitted to every pose (a whole clip: no jumping)
        up = np.array([0.0, 0.0, 1.0]) if str(UsdGeom.GetStageUpAxis(asset.stage)) == "Z" else np.array([0.0, 1.0, 0.0])
        view = _view_direction(asset.bind_points, up)
        right = np.cross(up, view)
        right /= np.linalg.norm(right)
        cam_up = np.cross(view, right)
        fit = list(fit) or [None]
        step = max(1, len(fit) // 12)
        pts = np.concatenate([asset.bind_points if p is None else p.points for p in fit[::step]]
                             + [p.source_points for p in fit[::step] if p is not None and p.source_points is not None])
        spheres = [(p.centers, p.radii) for p in fit if p is not None]
        axes = np.stack([right, cam_up, view])
        lo, hi = (pts @ axes.T).min(0), (pts @ axes.T).max(0)
        for c, r in spheres:
            cc = c @ axes.T
            lo = np.minimum(lo, (cc - r[:, None]).min(0))
            hi = np.maximum(hi, (cc + r[:, None]).max(0))
        centre = axes.T @ ((lo + hi) / 2)
        half_w, half_h = (hi[:2] - lo[:2]) / 2
        depth = (hi[2] - lo[2]) / 2
        cam = pl.camera
        cam.focal_point = tuple(centre)
        cam.position = tuple(centre + view * (depth * 4 + 1e-3))
        cam.up = tuple(cam_up)
        pl.enable_parallel_projection()
        cam.parallel_scale = 1.08 * max(half_h, half_w * self.size[1] / self.size[0], 1e-6)
        pl.renderer.ResetCameraClippingRange()

    def frame(self, pose: Pose, caption: str | None = None) -> np.ndarray:
        """Draw ``pose``; returns the image ``(H, W, 3) uint8``."""
        pv, pl = self.pv, self.plotter  # noqa: F841
        self.mesh.points = pose.points
        if self.source is not None and pose.source_points is not None:
            self.source.points = pose.source_points
        rgb = self.base_rgb.copy()
        red = (np.array(FAIL_RGB) * 255).astype(np.uint8)
        for p in np.nonzero(pose.failing)[0]:
            rgb[self.part_faces[p]] = red
        self.mesh.cell_data["rgb"] = rgb
        for p, a in enumerate(self.spheres):
            a.SetPosition(*pose.centers[p])
            a.SetScale(float(pose.radii[p]))
            failing = bool(pose.failing[p])
            a.prop.color = FAIL_RGB if failing else tuple(self.colors[p])
            a.prop.opacity = 0.3 if failing else SPHERE_OPACITY
        if len(pose.outside):
            self.marks_poly.copy_from(pv.PolyData(pose.points[pose.outside].astype(np.float32)))
        self.marks.SetVisibility(bool(len(pose.outside)))
        label = pose.label
        if self.source is not None:
            label += f"\nfaint grey: the full mesh ({len(self.source.faces) // 4} faces) where it lies outside"
        if pose.failing.any():
            names = ", ".join(self.asset.part_joints[p].rsplit("/", 1)[-1] for p in np.nonzero(pose.failing)[0])
            label += f"\nFAIL: {names} ({len(pose.outside)} vertices outside)"
        self.text.SetInput(caption or label)
        pl.render()
        img = pl.screenshot(return_img=True)
        return np.ascontiguousarray(img[..., :3])

    def close(self):
        self.plotter.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def render_image(asset, pose: Pose, size=(800, 600), source: SourceMesh | None = None) -> np.ndarray:
    """One pose as an ``(H, W, 3) uint8`` image, camera fitted to it."""
    with Renderer(asset, size, fit=[pose], source=source) as r:
        return r.frame(pose)


def png_bytes(img: np.ndarray, colors: int | None = 256) -> bytes:
    """PNG-encode an ``(H, W, 3) uint8`` image (palette-quantized to ``colors`` to keep it small)."""
    import io

    from PIL import Image

    im = Image.fromarray(img)
    if colors:
        im = im.quantize(colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    buf = io.BytesIO()
    im.save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def render_png(asset, out, clip=None, time=None, size=(800, 600), source: SourceMesh | None = None) -> Pose:
    """Write a PNG of the bind pose or ``clip`` at ``time`` (with ``source`` drawn faint
    behind); returns the pose drawn."""
    pose = pose_at(asset, clip, time, source)
    write_atomic(out, png_bytes(render_image(asset, pose, size, source)))
    return pose


def gif_times(times, max_frames: int = 60) -> np.ndarray:
    """At most ``max_frames`` of ``times``, evenly subsampled (first frame kept)."""
    times = np.asarray(times)
    step = max(1, int(np.ceil(len(times) / max_frames)))
    return times[::step]


def render_gif(asset, out, clip=None, size=(480, 360), max_frames=60, source: SourceMesh | None = None) -> list:
    """Write an animated GIF of ``clip`` (default the first), frames subsampled to at most
    ``max_frames``, played at the clip's speed (with ``source`` drawn faint behind); returns the
    poses drawn."""
    import io

    from PIL import Image

    check_drawable(asset)
    if not asset.clips:
        raise RenderError(f"{asset.path}: has no clips to animate (render a .png of the bind pose instead)")
    c = _find_clip(asset, clip) if clip is not None else asset.clips[0]
    if len(c.times) == 0:
        raise RenderError(f"clip {c.name!r} has no frames")
    times = gif_times(c.times, max_frames)
    ps = poses(asset, c.name, times, source)
    tcps = float(asset.stage.GetTimeCodesPerSecond()) or 24.0
    dt = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    ms = max(20, int(round(1000.0 * dt / tcps)))
    frames = []
    with Renderer(asset, size, fit=ps, source=source) as r:
        for p in ps:
            im = Image.fromarray(r.frame(p))
            frames.append(im.quantize(colors=128, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE))
    buf = io.BytesIO()
    frames[0].save(buf, format="GIF", save_all=True, append_images=frames[1:], duration=ms, loop=0)
    write_atomic(out, buf.getvalue())
    return ps
