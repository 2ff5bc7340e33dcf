"""Benchmarks on real characters (issue 22 item 1: benchmarks that cannot flatter us).

The synthetic rows of :mod:`bench.validate` and :mod:`bench.runtime` use spheres the benchmark
chose (loose ones settle every (part, frame) pair in test K).  The rows here run on corpus
characters (``../shared/corpus`` beside the repository, or ``$COLOSSUS_CORPUS``) with the spheres
the importer really writes, plus one clip repeated in time to ~1,000 frames.  Each row prints the
tier split beside its ratio: test K / test D / exact skinning for the sampled proof and the chord
bound / per-vertex chord / subdivision for the continuous certificate (the counts
``colossus validate`` prints), and for the import, the continuous certificate's split in the
spheres stage.

:class:`Characters` imports them once per bench run into a temporary folder (timed apart: the
import rows); ``colossus bench --only import|validate|runtime`` share it.  Absolute times are
this machine's; the ratios are against baselines run in the same process on the same data
(``UsdSkel.SkinPointsLBS``, usd-core's C++ skinning, and trimesh for the game frame).
"""

from __future__ import annotations

import os
import resource
import shutil
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from .runtime import _median_time as _median  # one timing loop for every runtime row

#: (label, path under the corpus).  The quick run uses the first one only.
CHARACTERS = (
    ("RiggedFigure", "khronos/RiggedFigure.gltf"),
    ("CesiumMan", "realworld/threejs_r121_CesiumMan.glb"),
    ("RobotExpressive", "realworld/threejs_r121_RobotExpressive.glb"),
    ("Fox", "khronos/Fox.glb"),
    ("Godot mannequin", "realworld/godot_mannequiny.glb"),
)
#: The character whose longest clip is repeated in time (forward, backward, forward ...) to at
#: least :data:`TILED_FRAMES` frames on a copy of its asset.
TILED_CHARACTER = "Godot mannequin"
TILED_FRAMES = 1000
INTERVAL_NAMES = ("chord", "vertex_chord", "subdivided", "failed", "undecided", "not_checked")


def corpus_dir() -> str | None:
    """The corpus folder: ``$COLOSSUS_CORPUS``, else ``../shared/corpus`` beside the repository
    (``/work/shared/corpus`` for a worktree in ``/work``); None when absent."""
    env = os.environ.get("COLOSSUS_CORPUS")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for cand in ([env] if env else []) + [os.path.join(root, "..", "shared", "corpus")]:
        if cand and os.path.isdir(cand):
            return os.path.abspath(cand)
    return None


def _cpu():
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def _pct(counts, names):
    tot = max(int(sum(counts)), 1)
    return " / ".join(f"{n} {c / tot:.0%}" for n, c in zip(names, counts))


def tiers_text(tiers) -> str:
    """``K a% / D b% / exact c%`` of (part, frame) pairs."""
    return _pct([tiers["K"], tiers["D"], tiers["exact"]], ("K", "D", "exact"))


def intervals_text(iv) -> str:
    """``chord a% / per-vertex b% / subdivided c%`` of (part, interval) pairs (and any others)."""
    s = _pct([iv["chord"], iv["vertex_chord"], iv["subdivided"]], ("chord", "per-vertex", "subdivided"))
    rest = {k: iv[k] for k in INTERVAL_NAMES[3:] if iv.get(k)}
    return s + "".join(f", {k} {v}" for k, v in rest.items())


@contextmanager
def _count_spheres_intervals(into: dict):
    """Count the continuous certificate's (part, interval) statuses while the import's spheres
    stage runs it (growth mode), by wrapping :func:`runtime.certify.continuous` for the duration:
    measurement only, the function and its results are untouched."""
    from colossus.runtime import certify

    orig = certify.continuous

    def counted(*a, **kw):
        c = orig(*a, **kw)
        st = np.bincount(c.status.ravel().astype(np.int64), minlength=6)
        for k, name in enumerate(INTERVAL_NAMES):
            into[name] = into.get(name, 0) + int(st[k])
        into["subdivisions"] = into.get("subdivisions", 0) + int(c.subdivided)
        return c

    certify.continuous = counted
    try:
        yield into
    finally:
        certify.continuous = orig


@contextmanager
def reference_paths():
    """Run the proof and the spheres stage on the reference paths the compiled ones replaced (issue
    22 items 2-3): the continuous certificate's levels B and C one numpy call per node
    (``certify.BATCHED = False``) and the sampled proof's exact tier skinning every vertex of a part
    (``certify.CHUNKED = False``, also the default for now): the "before" of the rows, in the same
    process, same results."""
    from colossus.runtime import certify

    old = certify.BATCHED, certify.CHUNKED
    certify.BATCHED, certify.CHUNKED = False, False
    try:
        yield
    finally:
        certify.BATCHED, certify.CHUNKED = old


@dataclass
class Character:
    """One imported corpus character (or the tiled copy)."""

    name: str
    source: str
    asset: str
    import_wall: float = 0.0
    import_cpu: float = 0.0
    stages: dict = field(default_factory=dict)
    spheres_intervals: dict = field(default_factory=dict)
    vertices: int = 0
    triangles: int = 0
    joints: int = 0
    parts: int = 0
    clips: int = 0
    frames: int = 0
    ref_wall: float = 0.0          # the import again on the reference paths (:func:`reference_paths`)
    ref_cpu: float = 0.0
    ref_spheres: float = 0.0
    ref_same: bool = True
    only_clip: str | None = None   # the tiled copy: prove / pose this clip alone
    note: str = ""
    error: str = ""


class Characters:
    """The corpus characters imported once per bench run (a temporary folder, removed by
    :meth:`close`).  ``quick``: the first character only, no tiled clip."""

    def __init__(self, quick: bool = False, echo=print, names=None):
        self.quick = quick
        self.echo = echo
        self.corpus = corpus_dir()
        self.items: list[Character] = []
        self._tmp = None
        self._names = names
        self.loaded = False

    def load(self) -> list[Character]:
        if self.loaded:
            return self.items
        self.loaded = True
        if self.corpus is None:
            self.echo("real characters: skipped (no corpus: ../shared/corpus beside the repository, or $COLOSSUS_CORPUS)")
            return self.items
        from colossus.pipeline.run import import_asset

        self._tmp = tempfile.mkdtemp(prefix="colossus-bench-real-")
        want = CHARACTERS[:1] if self.quick else CHARACTERS
        if self._names:
            want = [c for c in CHARACTERS if c[0] in self._names]
        missing = [rel for _, rel in want if not os.path.isfile(os.path.join(self.corpus, rel))]
        if missing:
            self.echo(f"real characters: not in the corpus, skipped: {', '.join(missing)}")
        for name, rel in want:
            src = os.path.join(self.corpus, rel)
            if not os.path.isfile(src):
                continue
            out = os.path.join(self._tmp, os.path.splitext(os.path.basename(rel))[0] + ".usda")
            ch = Character(name, rel, out)
            counts: dict = {}
            c0, t0 = _cpu(), time.perf_counter()
            try:
                with _count_spheres_intervals(counts):
                    res = import_asset(src, out)
            except Exception as e:  # a corpus file the importer refuses is a row, not a crash
                ch.error = f"{type(e).__name__}: {e}"
                self.items.append(ch)
                continue
            ch.import_wall, ch.import_cpu = time.perf_counter() - t0, _cpu() - c0
            ch.stages = {r.stage: r.seconds for r in res.reports}
            c0, t0 = _cpu(), time.perf_counter()
            with reference_paths():
                ref = import_asset(src, out + ".ref.usda")
            ch.ref_wall, ch.ref_cpu = time.perf_counter() - t0, _cpu() - c0
            ch.ref_spheres = {r.stage: r.seconds for r in ref.reports}.get("spheres", 0.0)
            with open(out, "rb") as f1, open(out + ".ref.usda", "rb") as f2:
                ch.ref_same = f1.read() == f2.read()
            ch.spheres_intervals = counts
            self._describe(ch)
            self.items.append(ch)
        if not self.quick and not self._names:
            base = next((c for c in self.items if c.name == TILED_CHARACTER and not c.error), None)
            if base is not None:
                self.items.append(tile_clip(base, TILED_FRAMES, self._tmp))
        return self.items

    @staticmethod
    def _describe(ch: Character):
        from colossus.validators.asset import LoadedAsset, open_stage
        a = LoadedAsset(open_stage(ch.asset), ch.asset)
        ch.vertices = int(a.n)
        ch.triangles = int(len(a.tris)) if a.tris is not None else 0
        ch.joints = len(a.joints)
        ch.parts = len(a.part_joints)
        clips = [c for c in a.clips if ch.only_clip in (None, c.name)]
        ch.clips = len(clips)
        ch.frames = int(sum(len(c.times) for c in clips))

    def close(self):
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None


def tile_clip(base: Character, frames: int, folder: str) -> Character:
    """A copy of ``base``'s asset whose longest clip is repeated in time, forward then backward
    (ping-pong: 0..n-1, n-2..0, 1..n-1, ...), to at least ``frames`` frames on the clip's own
    frame step.  Every interval of the long clip is an interval of the original one (traversed
    either way; UsdSkel's lerp and slerp are symmetric), so the importer's spheres still hold
    and the proof has the same work per interval, only ~1,000 frames of it."""
    from pxr import Sdf, Usd, UsdSkel

    stage = Usd.Stage.Open(base.asset)
    anims = [UsdSkel.Animation(p) for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]
    attrs = ("translations", "rotations", "scales")

    def times_of(a):
        ts = set()
        for n in attrs:
            ts.update(a.GetPrim().GetAttribute(n).GetTimeSamples())
        return sorted(ts)

    anim = max(anims, key=lambda a: len(times_of(a)))
    t = np.array(times_of(anim))
    n = len(t)
    out = os.path.join(folder, os.path.splitext(os.path.basename(base.asset))[0] + "_tiled.usda")
    ch = Character(f"{base.name} {anim.GetPrim().GetName()} x{frames}", base.source, out,
                   only_clip=anim.GetPrim().GetName())
    if n < 2:
        ch.error = "no clip of 2 frames or more to tile"
        return ch
    step = float(np.median(np.diff(t)))
    period = list(range(n)) + list(range(n - 2, 0, -1))  # 0..n-1, n-2..1 (then 0 again)
    idx = [period[k % len(period)] for k in range(max(frames, n))]
    values = {nm: [anim.GetPrim().GetAttribute(nm).Get(float(t[i])) for i in range(n)] for nm in attrs}
    layer = Sdf.Layer.FindOrOpen(base.asset)
    text = layer.ExportToString()
    new = Sdf.Layer.CreateAnonymous(".usda")
    new.ImportFromString(text)
    path = anim.GetPrim().GetPath()
    for nm in attrs:
        ap = path.AppendProperty(nm)
        if new.GetAttributeAtPath(ap) is None or values[nm][0] is None:
            continue
        for tt in new.ListTimeSamplesForPath(ap):
            new.EraseTimeSample(ap, tt)
        for k, i in enumerate(idx):
            new.SetTimeSample(ap, float(t[0] + k * step), values[nm][i])
    new.endTimeCode = max(new.endTimeCode, float(t[0] + (len(idx) - 1) * step))
    new.Export(out)
    ch.note = f"{anim.GetPrim().GetName()} ({n} frames) repeated forward and backward to {len(idx)} frames"
    Characters._describe(ch)
    return ch


# ------------------------------------------------------------------------------- rows
def format_import_rows(items) -> str:
    lines = ["real characters: import (once per bench run, into a temporary folder; the spheres stage runs the "
             "continuous certificate to grow the spheres: its (part, interval) split)"]
    for c in items:
        if c.only_clip:
            lines.append(f"  {c.name:<40} (a copy of {TILED_CHARACTER}'s asset: {c.note}; not imported)")
            continue
        if c.error:
            lines.append(f"  {c.name:<40} import refused: {c.error}")
            continue
        sp = c.stages.get("spheres", 0.0)
        lines.append(f"  {c.name:<40} {c.vertices:>6} verts {c.parts:>3} parts {c.clips:>3} clips {c.frames:>5} frames: "
                     f"total {c.import_wall:7.2f} s wall, {c.import_cpu:7.2f} s CPU; spheres stage {sp:7.2f} s "
                     f"({sp / max(c.stages.get('total', c.import_wall), 1e-9):.0%}) [{intervals_text(c.spheres_intervals)}]")
        if c.ref_cpu:
            lines.append(f"  {'':<40} before (reference paths, this process): {c.ref_wall:7.2f} s wall, {c.ref_cpu:7.2f} s CPU, "
                         f"spheres {c.ref_spheres:7.2f} s; now {c.ref_cpu / max(c.import_cpu, 1e-9):.2f}x faster (CPU), "
                         f"spheres {c.ref_spheres / max(sp, 1e-9):.2f}x; "
                         f"{'the same asset' if c.ref_same else 'ASSETS DIFFER'}")
    return "\n".join(lines)


def _lbs_time(points, jidx, jw, xforms, serial, repeat=3, shapes=None):
    """Seconds of ``UsdSkel.SkinPointsLBS`` over every frame of ``xforms`` (F, J, 4, 4)
    column-vector skinning transforms (best of ``repeat``); ``shapes`` (:func:`_shape_weights`):
    each frame's points first deformed by usd-core's blend shapes (``BlendShapeQuery.
    ComputeDeformedPoints``, UsdSkel's order: shapes, then skinning)."""
    from pxr import Gf, UsdSkel, Vt

    from colossus.runtime import schema
    ji = Vt.IntArray.FromNumpy(np.ascontiguousarray(jidx, dtype=np.int32).ravel())
    w = Vt.FloatArray.FromNumpy(np.ascontiguousarray(jw, dtype=np.float32).ravel())
    k = jidx.shape[1]
    gb = Gf.Matrix4d(1)
    mats = [Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(m)) for m in schema.row_vector(xforms)]
    src = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32))
    bq, offsets, indices, weights = shapes if shapes is not None else (None, None, None, [None] * len(mats))
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for m, sub in zip(mats, weights):
            p = Vt.Vec3fArray(src)
            if bq is not None:
                bq.ComputeDeformedPoints(*sub, indices, offsets, p)
            UsdSkel.SkinPointsLBS(gb, m, ji, w, k, p, serial)
        best = min(best, time.perf_counter() - t0)
    return best


def _shape_weights(path, clip_times):
    """Per frame of ``clip_times`` ([(clip name, times)]), usd-core's sub-shape weights of the
    asset's skinned mesh (the clip's variant selected, ``AnimQuery.ComputeBlendShapeWeights``,
    remapped to the mesh, ``BlendShapeQuery.ComputeSubShapeWeights``), the query and its offsets
    and indices: what the shapes-then-skinning baseline is given (computed outside its timing, as
    the joint transforms are)."""
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(path)
    vset = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("clip")
    frames, bq = [], None
    for name, times in clip_times:
        if vset:
            vset.SetVariantSelection(name)
        cache = UsdSkel.Cache()
        root = next(UsdSkel.Root(p) for p in stage.Traverse() if p.IsA(UsdSkel.Root))
        cache.Populate(root, Usd.PrimDefaultPredicate)
        (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
        sq = cache.GetSkelQuery(binding.GetSkeleton())
        (q,) = [t for t in binding.GetSkinningTargets() if t.GetPrim().IsA(UsdGeom.Mesh)]
        bq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(q.GetPrim()))
        for t in times:
            w = q.GetBlendShapeMapper().Remap(sq.GetAnimQuery().ComputeBlendShapeWeights(Usd.TimeCode(float(t))))
            frames.append(bq.ComputeSubShapeWeights(w))
    return bq, bq.ComputeSubShapePointOffsets(), bq.ComputeBlendShapePointIndices(), frames


def validate_row(ch: Character, repeat: int = 2) -> dict:
    """The whole proof ``colossus validate`` runs (read, sampled proof, continuous certificate)
    on one character, beside ``UsdSkel.SkinPointsLBS`` skinning every vertex at every frame it
    checks (joint transforms given to the baseline, computed outside its timing).  The proof's
    two parts are each the best of ``repeat`` runs, the baseline the best of 3."""
    from colossus.validators.asset import LoadedAsset, open_stage
    from colossus.validators.frameproof import prove, skinning_transforms

    t0 = time.perf_counter()
    a = LoadedAsset(open_stage(ch.asset), ch.asset)
    ok, why = a.ready("proof")
    if not ok:
        return {"name": ch.name, "error": f"asset not ready for the proof: {why}"}
    rig = a.rig
    t_read = time.perf_counter() - t0
    clips = [ch.only_clip] if ch.only_clip else None
    t_sampled = t_cont = np.inf
    for _ in range(repeat):  # best of ``repeat`` (a shared machine's noise only ever adds time)
        proof = prove(a, clips=clips)
        t_cont = min(t_cont, proof.continuous_seconds)
        t_sampled = min(t_sampled, proof.seconds - proof.continuous_seconds)
    ref_sampled = ref_cont = np.inf
    with reference_paths():  # the "before": the same proof on the reference paths, same process
        for _ in range(repeat):
            ref = prove(a, clips=clips)
            ref_cont = min(ref_cont, ref.continuous_seconds)
            ref_sampled = min(ref_sampled, ref.seconds - ref.continuous_seconds)
    same = (ref.tiers == proof.tiers and ref.intervals == proof.intervals and ref.between == proof.between
            and [r.vertex for r in ref.results] == [r.vertex for r in proof.results])
    xs = []
    t_joints = 0.0  # what the proof spends reading joint transforms (UsdSkel.AnimQuery), timed apart
    for c in a.clips:
        if clips is not None and c.name not in clips or len(c.times) == 0:
            continue
        tj = time.perf_counter()
        skel = a.skel_transforms(a.anim_local(c, c.times))
        t_joints += time.perf_counter() - tj
        xs.append(skinning_transforms(skel, a.inv_bind, rig.geom_bind, rig.world))
    x = np.concatenate(xs)
    par = _lbs_time(rig.points, rig.joint_indices, rig.joint_weights, x, False)
    ser = _lbs_time(rig.points, rig.joint_indices, rig.joint_weights, x, True)
    shaped = None
    if rig.shapes is not None and len(rig.shapes) and rig.skinning_method == "classicLinear":
        ct = [(c.name, c.times) for c in a.clips if (clips is None or c.name in clips) and len(c.times)]
        shaped = _lbs_time(rig.points, rig.joint_indices, rig.joint_weights, x, False,
                           shapes=_shape_weights(ch.asset, ct))
    passed = all(r.failing_times == 0 for r in proof.results) and not proof.between
    return {"name": ch.name, "vertices": len(rig.points), "parts": rig.P, "frames": len(x), "read_s": t_read,
            "sampled_s": t_sampled, "joints_s": t_joints, "continuous_s": t_cont,
            "sampled_no_read_vs_lbs": par / max(t_sampled - t_joints, 1e-9), "lbs_parallel_s": par, "lbs_serial_s": ser,
            "tiers": dict(proof.tiers), "intervals": dict(proof.intervals), "passed": passed,
            "sampled_vs_lbs": par / t_sampled, "continuous_over_sampled": t_cont / t_sampled,
            "whole_vs_lbs": par / (t_read + t_sampled + t_cont), "ref_sampled_s": ref_sampled,
            "ref_continuous_s": ref_cont, "ref_same": same, "ref_sampled_vs_lbs": par / ref_sampled,
            "ref_continuous_over_sampled": ref_cont / ref_sampled,
            "ref_whole_vs_lbs": par / (t_read + ref_sampled + ref_cont),
            "shapes": 0 if rig.shapes is None else len(rig.shapes), "shapes_lbs_parallel_s": shaped}


def _s(sec: float) -> str:
    return f"{sec:.3f} s" if sec >= 1 else f"{sec * 1e3:.2f} ms"


def format_validate_rows(rows) -> str:
    lines = ["real characters: the frame proof with the importer's spheres, every clip (speed ratios: "
             "SkinPointsLBS parallel seconds / ours, > 1 means we are faster; the sampled proof's time includes "
             "reading the joint transforms through UsdSkel.AnimQuery, the baseline is given them)"]
    for r in rows:
        if r.get("error"):
            lines.append(f"  {r['name']:<40} {r['error']}")
            continue
        lines += [f"  {r['name']:<40} {r['vertices']:>6} verts {r['parts']:>3} parts {r['frames']:>5} frames; "
                  f"SkinPointsLBS parallel {_s(r['lbs_parallel_s'])}, serial {_s(r['lbs_serial_s'])}; "
                  f"verdict {'PASS' if r['passed'] else 'FAIL'}",
                  f"    sampled proof     {_s(r['sampled_s']):>10} = {r['sampled_vs_lbs']:6.2f}x the speed of SkinPointsLBS   "
                  f"[{tiers_text(r['tiers'])}]; without reading the joint transforms ({_s(r['joints_s'])}, "
                  f"given to the baseline) {r['sampled_no_read_vs_lbs']:.2f}x",
                  *([f"    blend shapes ({r['shapes']}): usd-core's shapes then SkinPointsLBS (BlendShapeQuery."
                     f"ComputeDeformedPoints, parallel) {_s(r['shapes_lbs_parallel_s'])}: the sampled proof is "
                     f"{r['shapes_lbs_parallel_s'] / r['sampled_s']:.2f}x its speed"]
                    if r.get("shapes_lbs_parallel_s") else []),
                  f"    continuous cert.  {_s(r['continuous_s']):>10} = {r['continuous_over_sampled']:6.2f}x the sampled "
                  f"proof   [{intervals_text(r['intervals'])}]",
                  f"    whole proof (read {_s(r['read_s'])} + sampled + continuous) = {r['whole_vs_lbs']:6.2f}x "
                  "the speed of SkinPointsLBS",
                  f"    before (reference paths, this process): sampled {_s(r['ref_sampled_s'])} = "
                  f"{r['ref_sampled_vs_lbs']:.2f}x SkinPointsLBS, continuous {_s(r['ref_continuous_s'])} = "
                  f"{r['ref_continuous_over_sampled']:.2f}x its sampled proof, whole {r['ref_whole_vs_lbs']:.2f}x; now "
                  f"sampled {r['ref_sampled_s'] / max(r['sampled_s'], 1e-12):.2f}x and continuous "
                  f"{r['ref_continuous_s'] / max(r['continuous_s'], 1e-12):.2f}x faster; "
                  f"{'same results' if r['ref_same'] else 'RESULTS DIFFER'}"]
    return "\n".join(lines)


def runtime_row(ch: Character, repeat=50) -> dict:
    """``col.pose`` (joints, the full skin, the part and culling spheres) vs ``UsdSkel.SkinPointsLBS``
    at the same time (skinning transforms precomputed by usd-core), and a game frame (pose + 1
    sphere + 16 rays, :func:`bench.runtime.game_frame`) vs the same frame with trimesh
    (:mod:`bench.runtime` row 2), on the character's longest clip."""
    import trimesh
    from pxr import Gf, Usd, UsdSkel, Vt

    from colossus.bench.runtime import game_frame, game_frame_queries
    from colossus.runtime import load_collider

    col = load_collider(ch.asset)
    clip = ch.only_clip or max(col.clips, key=lambda c: len(col.frame_times(c)))
    times = col.frame_times(clip)
    rng = np.random.default_rng(0)
    ts = iter(rng.uniform(times[0], times[-1], 10 ** 6))
    pose = col.pose(clip, float(times[len(times) // 2]))

    def pose_update():
        p = col.pose(clip, next(ts), out=pose)
        return p.points, p.spheres

    ours1 = _median(pose_update, repeat)
    stage = Usd.Stage.Open(ch.asset)
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache.Populate(root, Usd.TraverseInstanceProxies())
    mesh_prim = next(p for p in stage.Traverse() if p.GetTypeName() == "Mesh" and p.HasAPI(UsdSkel.BindingAPI))
    skel_prim = UsdSkel.BindingAPI(mesh_prim).GetSkeleton().GetPrim()
    skq = cache.GetSkelQuery(UsdSkel.Skeleton(skel_prim))
    anim_prim = stage.GetPrimAtPath(skel_prim.GetPath().GetParentPath().AppendChild(clip))
    if anim_prim and anim_prim.IsValid():  # the clip's own animation bound, as the runtime poses it
        UsdSkel.BindingAPI(skel_prim).GetAnimationSourceRel().SetTargets([anim_prim.GetPath()])
        cache = UsdSkel.Cache()
        cache.Populate(root, Usd.TraverseInstanceProxies())
        skq = cache.GetSkelQuery(UsdSkel.Skeleton(skel_prim))
    t_mid = float(times[len(times) // 2])
    xf = skq.ComputeSkinningTransforms(t_mid)
    b = UsdSkel.BindingAPI(mesh_prim)
    ji, jw = b.GetJointIndicesPrimvar().Get(), b.GetJointWeightsPrimvar().Get()
    k = b.GetJointIndicesPrimvar().GetElementSize()
    rest = mesh_prim.GetAttribute("points").Get()
    gbv = b.GetGeomBindTransformAttr().Get()
    gb = gbv if gbv is not None else Gf.Matrix4d(1)

    def usd_lbs():
        p = Vt.Vec3fArray(rest)
        UsdSkel.SkinPointsLBS(gb, xf, ji, jw, k, p, False)
        return p

    base1 = _median(usd_lbs, repeat)
    frame = game_frame(col, clip)
    ours2 = _median(frame, repeat)
    tris = col.data.triangles
    p0 = col.pose(clip, t_mid)
    player, r, o, dirs = game_frame_queries(p0, col.size(), np.random.default_rng(0))
    dn = dirs / np.linalg.norm(dirs, axis=1)[:, None]

    def trimesh_frame():
        pts = np.asarray(usd_lbs(), dtype=np.float64)
        m = trimesh.Trimesh(pts, tris, process=False)
        m.ray.intersects_first(o, dn)
        trimesh.proximity.closest_point(m, player[None])

    base2 = _median(trimesh_frame, max(5, repeat // 5), warm=1)
    step_s, swept_s, query_s = _controller_steps(col, clip, repeat)
    return {"step_s": step_s, "swept_step_s": swept_s, "query_s": query_s, "name": ch.name, "vertices": len(col.data.rest_points), "parts": col.parts, "clip": clip,
            "pose_s": ours1, "lbs_s": base1, "pose_vs_lbs": base1 / ours1,
            "frame_s": ours2, "trimesh_frame_s": base2, "frame_vs_trimesh": base2 / ours2,
            "embree": bool(trimesh.ray.has_embree)}


def format_runtime_rows(rows) -> str:
    lines = ["real characters: runtime on the importer's asset (longest clip; ratio = baseline / ours)"]
    for r in rows:
        if r.get("error"):
            lines.append(f"  {r['name']:<40} {r['error']}")
            continue
        lines.append(f"  {r['name']:<40} {r['vertices']:>6} verts {r['parts']:>3} parts: pose update (skin + spheres) "
                     f"{r['pose_s'] * 1e3:.3f} ms vs SkinPointsLBS {r['lbs_s'] * 1e3:.3f} ms = {r['pose_vs_lbs']:.2f}x; "
                     f"game frame (pose + 1 sphere + 16 rays) {r['frame_s'] * 1e3:.3f} ms vs trimesh"
                     f"{' + embree' if r['embree'] else ''} {r['trimesh_frame_s'] * 1e3:.3f} ms = "
                     f"{r['frame_vs_trimesh']:.1f}x")
        if r.get("step_s") is not None:
            lines.append(f"  {'':<40} controller step standing (pose excluded): today {r['step_s'] * 1e6:.0f} us, "
                         f"body swept {r['swept_step_s'] * 1e6:.0f} us (goal < 100 us: "
                         f"{'met' if r['swept_step_s'] < 1e-4 else 'NOT met'}); continuous query per call "
                         f"(1x, its bound included) {r['query_s'] * 1e6:.0f} us")
    return "\n".join(lines)


def _controller_steps(col, clip, repeat):
    """Median controller step (pose excluded) of a player standing on the character through its
    clip at 60 Hz: today's (``sweep_body=False``) and with the body swept; and one continuous
    query per call (:func:`bench.runtime.bench_sweep`)."""
    from colossus.bench.runtime import bench_sweep
    from colossus.runtime.controller import CharacterController
    from colossus.runtime.script import start_position

    times = col.frame_times(clip)
    r = 0.035 * col.size()
    tc = col.data.time_codes_per_second
    steps = max(60, 2 * repeat)
    out = []
    for sweep in (False, True):
        a, b = col.pose(clip, float(times[0])), col.pose(clip, float(times[0]))
        ctrl = CharacterController(col, r, position=start_position(col, clip, r, 0.0), sweep_body=sweep)
        for _ in range(5):
            ctrl.step(a, a, 1 / 60)
        span = float(times[-1] - times[0])
        dts = []
        for k in range(steps):
            t = float(times[0]) + ((k + 1) * tc / 60) % span if span > 0 else float(times[0])
            b = col.pose(clip, t, out=b)
            t0 = time.perf_counter()
            ctrl.step(a, b, 1 / 60)
            dts.append(time.perf_counter() - t0)
            a, b = b, a
        out.append(float(np.median(dts)))
    q, _, _ = bench_sweep(col, clip, float(times[len(times) // 2]), speed=1.0, repeat=repeat)
    return out[0], out[1], q


def _rows(fn, items):
    out = []
    for ch in items:
        if ch.error:
            out.append({"name": ch.name, "error": f"skipped: {ch.error}"})
            continue
        try:
            out.append(fn(ch))
        except Exception as e:  # one character's trouble is its row, the others still run
            out.append({"name": ch.name, "error": f"failed: {type(e).__name__}: {e}"})
    return out


def _warm(items):
    """Compile (or load from numba's cache) every kernel the rows use, outside their timing: the
    proof of the smallest character and of the longest clip (the continuous certificate's
    compiled paths run only on clips big enough to pay for them)."""
    from colossus.validators.asset import LoadedAsset, open_stage
    from colossus.validators.frameproof import prove

    ok = [c for c in items if not c.error]
    picks = {min(ok, key=lambda c: c.vertices).name: None} if ok else {}
    big = max(ok, key=lambda c: c.frames / max(c.clips, 1), default=None)
    if big is not None:
        picks[big.name] = None
    for c in ok:
        if c.name in picks:
            a = LoadedAsset(open_stage(c.asset), c.asset)
            if a.ready("proof")[0]:
                clips = [c.only_clip] if c.only_clip else [max(a.clips, key=lambda k: len(k.times)).name]
                prove(a, clips=clips)


def run_validate(chars: Characters) -> list:
    items = chars.load()
    _warm(items)
    return _rows(validate_row, items)


def run_runtime(chars: Characters) -> list:
    return _rows(runtime_row, [c for c in chars.load() if not c.only_clip])
