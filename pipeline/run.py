"""The import stage chained in one visible place: read -> bake -> weld -> degenerate -> orient -> bind -> [simplify] -> parts -> quantize -> spheres -> write.

``simplify`` runs only with ``--target-faces`` / ``--max-deviation`` (a collision proxy); the
``degenerate`` test runs again on its proxy (it moves vertices)."""

from __future__ import annotations

import hashlib
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from . import __version__
from .errors import InputError, UsageError
from . import notcarried
from .model import SkinnedMesh
from .isolation import read_isolated
from .options import parse_max_deviation
from .stages import StageReport
from .stages.bake import bake
from .stages.bind import UNWEIGHTED_POLICIES, bind
from .stages.degenerate import degenerate as drop_degenerate
from .stages.orient import orient
from .stages.parts import parts
from .stages.simplify import simplify
from .stages.spheres import spheres
from .stages.weld import weld
from .stages.quantize import quantize
from .stages.write import check_output_path, write
from .tolerances import LARGEST_COORDINATE, PARTS_ANY_THRESHOLD, RESAMPLING_RELATIVE
from .xforms import degenerate

STAGES = ("read", "bake", "weld", "degenerate", "orient", "bind", "simplify", "parts", "quantize", "spheres", "write")
#: Stages that run only when asked for.
OPTIONAL_STAGES = ("simplify",)


@dataclass
class ImportSettings:
    """Every knob of ``colossus import`` (defaults are the command line's)."""

    up_axis: str = "Y"
    meters_per_unit: float = 1.0
    max_influences: int = 4
    unweighted: str = "error"
    parts: str = "dominant"
    min_part_faces: int = 1
    parts_threshold: float = PARTS_ANY_THRESHOLD
    meshes: list = field(default_factory=list)
    fps: float | None = None
    source_up_axis: str | None = None
    source_meters_per_unit: float | None = None
    target_faces: int | None = None
    max_deviation: str | None = None
    #: follow the source's references out of its folder (regular files only; runtime.references)
    allow_outside_references: bool = False

    @property
    def proxy(self) -> bool:
        """A simplified collision proxy was asked for."""
        return self.target_faces is not None or self.max_deviation not in (None, "")

    def stages(self) -> tuple:
        """The stages this import runs, in order."""
        return tuple(s for s in STAGES if s not in OPTIONAL_STAGES or (s == "simplify" and self.proxy))

    def check(self) -> None:
        if self.up_axis not in ("Y", "Z"):
            raise UsageError(f"--up-axis must be Y or Z, got {self.up_axis!r}")
        if not (self.meters_per_unit > 0):
            raise UsageError(f"--meters-per-unit must be positive, got {self.meters_per_unit}")
        if self.max_influences < 1:
            raise UsageError(f"--max-influences must be at least 1, got {self.max_influences}")
        if self.unweighted not in UNWEIGHTED_POLICIES:
            raise UsageError(f"--unweighted must be one of {', '.join(UNWEIGHTED_POLICIES)}")
        if self.parts not in ("dominant", "any"):
            raise UsageError(f"--parts must be dominant or any, got {self.parts!r}")
        if self.min_part_faces < 1:
            raise UsageError(f"--min-part-faces must be at least 1, got {self.min_part_faces}")
        if self.fps is not None and not (self.fps > 0):
            raise UsageError(f"--fps must be positive, got {self.fps}")
        if self.source_meters_per_unit is not None and not (self.source_meters_per_unit > 0):
            raise UsageError("--source-meters-per-unit must be positive")
        if self.target_faces is not None and self.target_faces < 4:
            raise UsageError(f"--target-faces must be at least 4, got {self.target_faces}")
        parse_max_deviation(self.max_deviation)


@dataclass
class ImportResult:
    mesh: SkinnedMesh
    reports: list
    seconds: float
    out_path: str

    def summary(self) -> dict:
        """The numbers of the summary table, JSON-able."""
        r = {rep.stage: rep for rep in self.reports}
        m = self.mesh
        frames = sum(c.frame_count for c in m.clips)
        return {
            "source": m.source.get("file"), "output": self.out_path,
            "vertices_in": r["read"].counts["vertices"], "vertices_out": m.vertex_count,
            "faces_in": r["read"].counts["faces"], "faces_out": m.face_count,
            "faces_flipped": r["orient"].counts.get("faces_flipped", 0),
            "degenerate_dropped": (r["degenerate"].counts["dropped"]
                                   + r["degenerate"].counts.get("dropped_after_simplify", 0)),
            "influences_dropped": r["bind"].counts["influences_dropped"] + r["bind"].counts["negligible_dropped"],
            "joints": m.joint_count, "parts": len(m.parts), "clips": len(m.clips), "frames": frames,
            "seconds": round(self.seconds, 4),
            "stage_seconds": {rep.stage: round(rep.seconds, 4) for rep in self.reports},
            "warnings": [w for rep in self.reports for w in rep.warnings],
            "not_carried": list(m.source.get(notcarried.SOURCE_KEY) or []),
            "stages": {rep.stage: {"counts": rep.counts, **({"details": rep.details} if rep.details else {})}
                       for rep in self.reports},
        }


def proxy_provenance(report) -> dict:
    """The ``customData["colossus"]["proxy"]`` dictionary of a simplified proxy (key paths
    :data:`runtime.schema.PROXY_SOURCE_FACES`, :data:`~runtime.schema.PROXY_MAX_DEVIATION`, ...)."""
    from colossus.runtime import schema

    c = report.counts
    w = c["worst"]
    out = {}
    for key, value in ((schema.PROXY_SOURCE_FACES, int(c["faces_in"])),
                       (schema.PROXY_MAX_DEVIATION, float(c["deviation"])),
                       (schema.PROXY_MEASURED_DEVIATION, float(c["sampled_deviation"])),
                       (schema.PROXY_WORST_CLIP, str(w["clip"])), (schema.PROXY_WORST_FRAME, int(w["frame"])),
                       (schema.PROXY_WORST_BONE, str(w["bone"])), (schema.PROXY_WORST_DIRECTION, str(w["direction"]))):
        out[key.split(":")[-1]] = value
    return out


def mesh_provenance(info: list) -> dict:
    """``{mesh name: {"kind": "skinned" | "rigid", "vertices": n[, "joint": name]}}`` for the
    asset's provenance (primitives of one mesh added up)."""
    out = {}
    for x in info:
        d = out.setdefault(x["name"], {"kind": x["kind"], "vertices": 0})
        d["vertices"] += int(x["vertices"])
        if x["kind"] != d["kind"]:
            d["kind"] = "skinned and rigid"
        if x.get("joint"):
            d["joint"] = x["joint"]
    return out


def sha256_of(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def check_read(mesh: SkinnedMesh, src) -> None:
    """What every stage assumes of a reader's result, checked once for every reader: faces,
    finite positions and weights, in-range joint indices, a positive frame rate, and finite,
    invertible bind and animated joint transforms.  Raises :class:`InputError` naming the file
    (a corrupt or hostile file otherwise ends in a singular-matrix failure or NaN warnings
    several stages later)."""
    m = mesh
    if m.face_count == 0:
        raise InputError(src, "the skinned mesh has no faces")
    with np.errstate(invalid="ignore"):
        off = ~(np.abs(m.positions) <= LARGEST_COORDINATE).all(axis=1)  # NaN counts too
    if off.any():
        raise InputError(src, f"{int(off.sum())} vertex position(s) are not finite or beyond +-{LARGEST_COORDINATE:g} "
                              "(float32 skinning would overflow)")
    w = m.joint_weights
    if not np.isfinite(w).all() or (w < 0).any():
        raise InputError(src, "skin weights are negative or not finite")
    ji = m.joint_indices
    if len(ji) and m.joint_count and (ji.min() < 0 or ji.max() >= m.joint_count):
        raise InputError(src, f"skin joint index out of range for {m.joint_count} joints")
    fps = m.time_codes_per_second
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(src, f"the file's frame rate ({fps:g}) is not a positive number (give --fps)")
    for what, mats in (("geometry bind transform", m.geom_bind[None]), ("bind transform", m.bind_transforms),
                       ("rest transform", m.rest_transforms)):
        bad = np.flatnonzero(degenerate(mats))
        if len(bad):
            who = f" of joint {m.joint_names[bad[0]]!r}" if what != "geometry bind transform" else ""
            raise InputError(src, f"the {what}{who} is not finite, not invertible (zero scale?) or huge")
    for c in m.clips:
        if not np.isfinite(c.times).all():
            raise InputError(src, f"clip {c.name!r} has non-finite time codes")
        bad = np.argwhere(degenerate(c.local))
        if len(bad):
            f, j = bad[0]
            raise InputError(src, f"clip {c.name!r} frame {f} (time {c.times[f]:g}): joint {m.joint_names[j]!r} has a "
                                  "transform that is not finite, not invertible (zero scale?) or huge")


def not_carried(m: SkinnedMesh) -> list:
    """What the reader met and does not carry exactly (:mod:`pipeline.notcarried` records): the
    reader's own list, and the morph targets / shape keys of the chosen meshes."""
    out = list(m.source.get(notcarried.SOURCE_KEY) or [])
    morph = m.source.get("morph_meshes") or {}
    if morph and not any(x["what"] == "morph_targets" for x in out):
        out.insert(0, notcarried.item(
            "morph_targets", list(morph),
            "morph targets / shape keys are not carried into the collider (it follows the skeleton only): "
            + ", ".join(f"{k} ({v})" for k, v in morph.items())))
    return out


def read_warnings(m: SkinnedMesh) -> list:
    """The reader's findings worth a warning line: its notes, one line per thing not carried
    (:func:`not_carried`), clips whose resampling off the source's keys errs more than the
    tolerance, no clip at all."""
    out = list(m.source.get("notes", []))
    out += [notcarried.warning_line(x) for x in not_carried(m)]
    for c in m.source.get("clip_info", []):
        if c.get("error_bound_relative", 0.0) > RESAMPLING_RELATIVE:
            out.append(f"clip {c['name']!r}: its keys fall between the {c['fps']:g} fps frames and resampling "
                       f"moves vertices up to {c['error_bound_relative']:.2g} x the model size "
                       f"(more than {RESAMPLING_RELATIVE:g}); import with --fps at the source's rate")
    for c in m.source.get("clip_info", []):
        if c.get("shown_pose"):
            out.append(f"the file has no animation: the pose it shows ({c['shown_pose_moves_relative']:.2g} x the "
                       f"model size off its bind pose) is the one-frame clip {c['name']!r}")
    if not m.clips:
        out.append("the file has no animation clip; spheres hold for the bind pose only")
    return out


def settings_from_provenance(settings: dict) -> ImportSettings:
    """The :class:`ImportSettings` an asset was made with, from its provenance ``settings``
    dictionary (empty strings stand for None; the mesh list was stored comma-separated)."""
    base = asdict(ImportSettings())
    out = {}
    for k, default in base.items():
        if k not in settings:
            continue
        v = settings[k]
        if k == "meshes":
            out[k] = [m for m in str(v).split(", ") if m] if not isinstance(v, (list, tuple)) else list(v)
        elif v == "" or v is None:
            out[k] = None if default is None else default
        elif isinstance(default, bool):
            out[k] = v if isinstance(v, bool) else str(v).lower() in ("1", "true", "yes")
        elif isinstance(default, float) or k in ("fps", "source_meters_per_unit"):
            out[k] = float(v)
        elif isinstance(default, int):
            out[k] = int(v)
        else:
            out[k] = v
    return ImportSettings(**out)


def read_baked(src, settings: ImportSettings | None = None) -> SkinnedMesh:
    """The source read and baked into the output convention exactly as ``import`` does (before
    welding and rounding): what ``colossus validate --source`` compares an asset with.  Read in
    a contained child and checked like import's read, so a hostile source is one InputError."""
    s = settings or ImportSettings()
    s.check()
    m = read_isolated(src, meshes=s.meshes or None, fps=s.fps, allow_outside=s.allow_outside_references)
    if s.source_up_axis or s.source_meters_per_unit:
        m = m.replace(up_axis=s.source_up_axis or m.up_axis,
                      meters_per_unit=s.source_meters_per_unit or m.meters_per_unit)
    check_read(m, src)
    return bake(m, s.up_axis, s.meters_per_unit)[0]


def build_collider(src, settings: ImportSettings | None = None, progress=None, stop_after: str | None = None,
                   strict: bool = False):
    """Run every stage but ``write``: returns ``(mesh, reports)``.

    ``progress(i, n, stage)`` is called before each stage when given.  ``stop_after`` ends the
    run after that stage (``"bind"``: the full mesh a proxy is simplified from; ``"simplify"``:
    the proxy, or the full mesh when the settings ask for none).  ``strict``: raise
    :class:`InputError` right after ``read`` when the reader met anything it does not carry
    exactly (:func:`not_carried`).
    """
    if stop_after not in (None, "bind", "simplify"):
        raise ValueError(f"stop_after: expected None, 'bind' or 'simplify', got {stop_after!r}")
    s = settings or ImportSettings()
    s.check()
    reports = []
    names = s.stages()

    def step(name, fn):
        if progress:
            progress(names.index(name), len(names), name)
        t0 = time.perf_counter()
        out = fn()
        rep = out[1]
        rep.seconds = time.perf_counter() - t0
        reports.append(rep)
        return out[0]

    def do_read():
        m = read_isolated(src, meshes=s.meshes or None, fps=s.fps, allow_outside=s.allow_outside_references)  # a native crash: one InputError
        if s.source_up_axis or s.source_meters_per_unit:
            m = m.replace(up_axis=s.source_up_axis or m.up_axis,
                          meters_per_unit=s.source_meters_per_unit or m.meters_per_unit)
        m = m.replace(source={**m.source, "path": os.fspath(src)})
        check_read(m, src)
        m.source[notcarried.SOURCE_KEY] = not_carried(m)
        info = m.source.get("mesh_info", [])
        rep = StageReport("read", counts={
            "vertices": m.vertex_count, "faces": m.face_count, "joints": m.joint_count,
            "clips": len(m.clips), "frames": sum(c.frame_count for c in m.clips),
            "format": m.source.get("format"), "meshes": len(m.source.get("meshes", [])),
            "skinned_meshes": sum(1 for x in info if x["kind"] == "skinned"),
            "rigid_meshes": sum(1 for x in info if x["kind"] == "rigid"),
            "weights_normalised": (m.source.get("weights_normalised") or {}).get("vertices", 0),
            "time_codes_per_second": m.time_codes_per_second},
            details={"clips": m.source.get("clip_info", []), "meshes": info,
                     "weights_normalised": m.source.get("weights_normalised", {}),
                     "meshes_left_out": m.source.get("meshes_left_out", [])})
        rep.warnings.extend(read_warnings(m))
        return m, rep

    mesh = step("read", do_read)
    if strict and mesh.source[notcarried.SOURCE_KEY]:
        raise InputError(src, notcarried.strict_refusal(mesh.source[notcarried.SOURCE_KEY]))
    mesh = step("bake", lambda: bake(mesh, s.up_axis, s.meters_per_unit))
    mesh = step("weld", lambda: weld(mesh))
    mesh = step("degenerate", lambda: drop_degenerate(mesh))
    mesh = step("orient", lambda: orient(mesh))
    mesh = step("bind", lambda: bind(mesh, s.max_influences, s.unweighted))
    if strict and mesh.source.get(notcarried.SOURCE_KEY):  # the trim of skin weights moves vertices
        raise InputError(src, notcarried.strict_refusal(mesh.source[notcarried.SOURCE_KEY]))
    if stop_after == "bind":
        return mesh, reports
    if s.proxy:
        mesh = step("simplify", lambda: simplify(mesh, s.target_faces, s.max_deviation, s.max_influences))
        mesh = _degenerate_again(mesh, reports)
    if stop_after == "simplify":
        return mesh, reports
    mesh = step("parts", lambda: parts(mesh, s.parts, s.min_part_faces, s.parts_threshold))
    # the spheres are proven on the clips exactly as the asset stores them (half-precision scales)
    mesh = step("quantize", lambda: quantize(mesh))
    mesh = step("spheres", lambda: _spheres(mesh, src))
    return mesh, reports


def _degenerate_again(mesh, reports):
    """The ``degenerate`` test on a simplified proxy (its collapses move vertices, and a face they
    leave may be thinner than the tolerance though it did not turn over): what it drops is added
    to the ``degenerate`` report as ``dropped_after_simplify`` (the proxy's deviation bound was
    measured with those faces, each at most a sliver of zero width), its time to the stage's."""
    t0 = time.perf_counter()
    out, rep = drop_degenerate(mesh)
    own = next(r for r in reports if r.stage == "degenerate")
    own.counts["dropped_after_simplify"] = rep.counts["dropped"]
    own.seconds += time.perf_counter() - t0
    return out


def _spheres(mesh, src):
    """The spheres stage; a joint transform that check_read found invertible but that is singular
    as stored (a scale below half precision's range, quantize) is the file's problem: one
    InputError, without the NumPy warnings that came before it (fuzz case 147 of campaign 12,
    kept in tests/pipeline/test_bad_input.py)."""
    import warnings

    from colossus.runtime.schema import scale_singularity

    for clip in mesh.stored_clips:  # a pose with no inverse, between frames too: the proof has no joint space
        bad = scale_singularity(clip)
        if bad is not None:
            t, j, why = bad
            raise InputError(src, f"clip {clip.name!r} time {t:g}: joint "
                                  f"{mesh.joint_names[int(clip.anim_to_skel[j])]!r} {why}, so its transform is not "
                                  "invertible as stored; corrupt or hostile file?")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            out = spheres(mesh)
        except np.linalg.LinAlgError:
            raise InputError(src, "a joint transform is not invertible as stored (a scale too small for "
                                  "half precision?); corrupt or hostile file?") from None
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out


def import_asset(src, out, settings: ImportSettings | None = None, progress=None, strict: bool = False,
                 build: dict | None = None, check=None) -> ImportResult:
    """Import the Blender export ``src`` and write the collider asset ``out`` (atomically).

    ``strict``: refuse (:class:`InputError`, nothing written) when the reader met anything it
    does not carry exactly (``--strict``; :mod:`pipeline.notcarried`).  ``build``: the build
    stamp of ``colossus build`` (its key and what went into it), stored in the provenance as
    ``customData["colossus"]["build"]``.  ``check(path, settings) -> None | str``: run on the
    written file before its rename (:func:`pipeline.stages.write.write`) with this import's
    :class:`ImportSettings`; a string refuses the asset (:class:`InputError`
    ``"<src>: <string>"``, nothing written).  The command line passes the validator's error rules
    (``cli.import_.error_rules``).

    Raises
    ------
    InputError : the input is unusable.
    OutputError : ``out`` cannot be written.
    UsageError : invalid settings.
    """
    s = settings or ImportSettings()
    t0 = time.perf_counter()
    check_output_path(out)  # fail before the expensive work
    mesh, reports = build_collider(src, s, progress, strict=strict)
    if progress:
        progress(len(s.stages()) - 1, len(s.stages()), "write")
    t1 = time.perf_counter()
    provenance = {
        "source": os.path.basename(os.fspath(src)), "sourceSha256": sha256_of(src),
        "importer": f"colossus {__version__}", "reader": mesh.source.get("reader", ""),
        "sourceFrame": mesh.source.get("frame", ""),
        "settings": {k: ("" if v is None else v) for k, v in asdict(s).items()},
        "meshes": mesh_provenance(mesh.source.get("mesh_info", [])),
    }
    if mesh.source.get("point_scale", 1.0) != 1.0:  # quantize.fold_point_scale: validate --source needs it
        provenance["pointScale"] = float(mesh.source["point_scale"])
    items = mesh.source.get(notcarried.SOURCE_KEY) or []
    if items:
        provenance[notcarried.PROVENANCE_KEY] = notcarried.to_provenance(items)
    simp = next((r for r in reports if r.stage == "simplify"), None)
    if simp is not None:
        provenance["proxy"] = proxy_provenance(simp)
    if build:
        provenance["build"] = dict(build)
    mesh, rep = write(mesh, out, provenance, check=None if check is None else (lambda path: check(path, s)))
    rep.seconds = time.perf_counter() - t1
    reports.append(rep)
    return ImportResult(mesh, reports, time.perf_counter() - t0, os.fspath(out))
