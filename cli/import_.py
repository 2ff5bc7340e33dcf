"""``colossus import``: a Blender export in, a USD collider asset out."""

from __future__ import annotations

import json
import os
import sys

import click

from colossus.cli._errors import interrupted_status, maps_errors
from colossus.pipeline.errors import OutputError, UsageError
from colossus.pipeline.tolerances import PARTS_ANY_THRESHOLD

LARGE_INPUT_BYTES = 4 * 2**20  # show a progress bar from this input size on (when stderr is a terminal)

#: Error rules the import does not rerun on the asset it writes: the frame proof (COL403 holds on
#: all frames, COL407 holds between frames), the most expensive checks, which the ``spheres``
#: stage has already made on the clips exactly as stored, with the same certificate
#: (``runtime.certify.continuous``); and the ``--source`` family (COL6xx), which needs the source.
NOT_RERUN = ("COL403", "COL407", "COL6")


def error_rules(path, settings) -> str | None:
    """The validator's error rules on the asset ``import`` has just written to the temporary file
    ``path``, before its rename (``pipeline.run.import_asset``'s ``check``), with the options the
    import's ``settings`` imply (``--max-influences`` for COL301, ``--max-deviation`` for COL701, as
    ``colossus validate`` takes them): None when none fails, else ``"<code>: <message>"`` of the
    first error finding (``(+N more)`` when there are others), which refuses the import.  Every
    error-severity rule runs but :data:`NOT_RERUN`: the structure (COL0xx, COL1xx), mesh
    (COL201-COL204, COL208, COL209), skin (COL3xx), parts (COL401, COL402, COL405), animation
    (COL5xx) and proxy (COL701) errors.  A module-level function, so that a batch import's worker
    processes receive it by name."""
    from colossus.validators.registry import all_rules
    from colossus.validators.runner import check_asset

    codes = [r.code for r in all_rules() if r.severity == "error" and not r.code.startswith(NOT_RERUN)]
    report = check_asset(path, select=codes, max_influences=settings.max_influences,
                         max_deviation=settings.max_deviation or None)
    errors = [f for f in report.findings if f.severity == "error"]
    if not errors:
        return None
    first = errors[0]
    more = f" (+{len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{first.code}: {first.message}{more}"


def _num(value, spec: str) -> str:
    """``format(value, spec)``, or ``n/a`` for a figure a degenerate input leaves undefined
    (a part whose vertices all coincide has no slack ratio)."""
    return "n/a" if value is None else format(value, spec)


def _stage_line(rep) -> str:
    c = rep.counts
    s = rep.stage
    if s == "read":
        meshes = ""
        if "skinned_meshes" in c:
            meshes = f", {c['skinned_meshes']} skinned + {c['rigid_meshes']} rigid meshes"
        norm = f", {c['weights_normalised']} weight sums normalised" if c.get("weights_normalised") else ""
        return (f"{c['vertices']} vertices, {c['faces']} triangles, {c['joints']} joints, {c['clips']} clips "
                f"({c['frames']} frames at {c['time_codes_per_second']:g} fps){meshes}{norm} [{c['format']}]")
    if s == "bake":
        return (f"{c['source_up_axis']}-up {c['source_meters_per_unit']:g} m/unit -> {c['up_axis']}-up "
                f"{c['meters_per_unit']:g} m/unit (x{c['scale_applied']:g})")
    if s == "weld":
        return f"{c['vertices_in']} -> {c['vertices_out']} vertices ({c['merged']} merged, {c['weight_conflicts']} weight conflicts)"
    if s == "degenerate":
        again = (f", {c['dropped_after_simplify']} more from the proxy"
                 if c.get("dropped_after_simplify") else "")
        return (f"{c['dropped']} zero-area triangles dropped{again} ({c['repeated_index']} with a repeated "
                f"vertex; area <= {c['area_threshold']:.2g}), {c['faces_out']} left")
    if s == "orient":
        return (f"{c['faces_flipped']} faces flipped, {c['shells']} shells ({c['closed_shells']} closed), "
                f"{c['nonmanifold_edges']} non-manifold edges")
    if s == "bind":
        return (f"{c['joints']} joints, <= {c['max_influences']} influences, {c['influences_dropped']} dropped, "
                f"{c['negligible_dropped']} negligible")
    if s == "parts":
        return f"{c['parts']} parts ({c['mode']}), {len(c.get('folded_joints', []))} joints folded"
    if s == "quantize":
        k = (f", root scale x{c['root_scale']:.6g} folded into the translations"
             if abs(c["root_scale"] - 1.0) > 1e-6 else "")
        return (f"{c['clips']} clips as stored (float3, quatf, half3){k}; moves a vertex "
                f"<= {c['storage_error_relative']:.2g} x size")
    if s == "spheres":
        return f"max radius {_num(c['max_radius'], '.4g')}, max slack x{_num(c['max_slack_ratio'], '.3f')}"
    if s == "simplify":
        return (f"{c['faces_in']} -> {c['faces_out']} faces, {c['closed_shells_out']}/{c['closed_shells_in']} closed shells "
                f"closed, deviation <= {_num(c['deviation'], '.4g')} ({_num(None if c['deviation_relative'] is None else 100 * c['deviation_relative'], '.3g')}% of size)")
    if s == "write":
        checked = f"; error rules passed in {c['check_seconds']:.3f} s" if "check_seconds" in c else ""
        return f"{c['path']} ({c['bytes']} bytes, {c.get('skinning_method', 'classicLinear')} skinning{checked})"
    return ""


def format_summary(result) -> str:
    s = result.summary()
    lines = [f"colossus import {s['source']} -> {s['output']}", ""]
    lines.append(f"  {'stage':<10} {'seconds':>8}  what it did")
    for rep in result.reports:
        lines.append(f"  {rep.stage:<10} {rep.seconds:8.3f}  {_stage_line(rep)}")
    lines.append(f"  {'total':<10} {s['seconds']:8.3f}")
    lines.append("")
    lines.append(f"  vertices {s['vertices_in']} in, {s['vertices_out']} out | zero-area triangles dropped "
                 f"{s['degenerate_dropped']} | faces flipped {s['faces_flipped']} | "
                 f"influences dropped {s['influences_dropped']} | parts {s['parts']} | clips {s['clips']} | frames {s['frames']}")
    lines += _source_lines(next(r for r in result.reports if r.stage == "read"), result.mesh)
    sph = next(r for r in result.reports if r.stage == "spheres")
    parts = sph.details.get("parts", [])
    if parts:
        lines.append("")
        faces = result.mesh.parts.face_offsets
        lines.append(f"  {'part':>4} {'joint':<20} {'faces':>6} {'vertices':>8} {'radius':>10} {'slack':>7} {'growth':>9}")
        for i, p in enumerate(parts):
            g = p.get("growth", 0.0)
            lines.append(f"  {i:>4} {str(p.get('joint'))[:20]:<20} {int(faces[i + 1] - faces[i]):>6} "
                         f"{p.get('vertices', 0):>8} {_num(p.get('radius'), '.4g'):>10} {_num(p.get('slack_ratio'), '.3f'):>7} "
                         f"{g / p['radius'] if p.get('radius') else 0.0:>9.2%}")
        lines.append("  (radius in joint space; slack = radius / tightest per-frame sphere; growth = how much of "
                     "the radius covers motion between frames beyond the frames' minimal sphere)")
    simp = next((r for r in result.reports if r.stage == "simplify"), None)
    if simp is not None:
        lines.append("")
        lines += proxy_lines(simp)
    for w in s["warnings"]:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def proxy_lines(rep) -> list:
    """The collision proxy's deviation: the bound, where the largest distance was measured
    (clip, frame, bone), and a table per clip."""
    c = rep.counts
    w = c["worst"]
    if not w["bone"]:
        return [f"  proxy: {c['faces_in']} -> {c['faces_out']} faces: the full mesh (deviation 0)"]
    where = "the bind pose" if w["frame"] in (-1, None) else f"clip {w['clip']} frame {w['frame']}"
    out = [f"  proxy: {c['faces_in']} -> {c['faces_out']} faces ({c['vertices_out']} vertices); deviation <= "
           f"{c['deviation']:.4g}; largest measured {w['measured']:.4g} at {where}, bone {w['bone']} ({w['direction']})"]
    clips = rep.details.get("clips", [])
    if clips:
        out.append(f"  {'clip':<24} {'frames':>6} {'deviation <=':>12} {'measured':>10} {'at frame':>8}")
        for r in clips:
            out.append(f"  {str(r['clip'])[:24]:<24} {r['frames']:>6} {r['deviation']:>12.4g} {r['measured']:>10.4g} "
                       f"{r['frame']:>8}")
        out.append(f"  {'(bind pose)':<24} {1:>6} {rep.details.get('bind_pose_deviation', 0):>12.4g} "
                   f"{rep.details.get('bind_pose_measured', 0):>10.4g} {'':>8}")
        out.append("  (deviation: upper bound of the two-sided distance between the proxy and the full skinned mesh, "
                   "stage units; measured: the largest distance found between them)")
    return out


#: Storage error bounds below this (relative to the model size) are float32 noise, not shown.
STORAGE_SHOWN = 1e-6


def _source_lines(read_rep, mesh=None) -> list:
    """Per mesh (skinned or rigid, vertices) and per clip (source keys, sampling, frames, error
    bound where keys fall between frames, and the bound on what the asset's storage types move,
    where its scales are not exactly 1) of the read stage and of ``mesh`` as written."""
    d = read_rep.details or {}
    lines = []
    from colossus.pipeline.run import mesh_provenance
    meshes = mesh_provenance(d.get("meshes") or [])
    if meshes:
        lines += ["", f"  {'mesh':<28} {'kind':<8} {'vertices':>8}  bound to"]
        for name, m in meshes.items():
            lines.append(f"  {str(name)[:28]:<28} {m['kind']:<8} {m['vertices']:>8}  {m.get('joint', '(its skin)')}")
    wn = d.get("weights_normalised") or {}
    if wn.get("vertices"):
        lines.append(f"  {wn['vertices']} vertices had weights not summing to 1 (sums {wn['min_sum']:g}..{wn['max_sum']:g}): normalised")
    clips = (mesh.source.get("clip_info") if mesh is not None else None) or d.get("clips") or []
    if clips:
        lines += ["", f"  {'clip':<24} {'keys':>5} {'frames':>6}  sampling"]
        for c in clips:
            bound = (f"; off-grid error <= {c['error_bound_relative']:.2g} x size"
                     if "error_bound_relative" in c else "")
            if c.get("storage_error_relative", 0.0) > STORAGE_SHOWN:
                bound += f"; stored (half-precision scales) error <= {c['storage_error_relative']:.2g} x size"
            lines.append(f"  {str(c['name'])[:24]:<24} {c['source_keys']:>5} {c['frames']:>6}  {c['sampling']}{bound}")
    return lines


@click.command("import", context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("srcs", metavar="SRC...", nargs=-1, required=True, type=click.Path(dir_okay=True, path_type=str))
@click.option("-o", "--output", "out", required=True, type=click.Path(path_type=str),
              help="Collider asset to write (.usda, .usdc or .usd); with several inputs, a directory.")
@click.option("--up-axis", type=click.Choice(["Y", "Z"], case_sensitive=False), default="Y", show_default=True,
              help="Up axis of the output.")
@click.option("--meters-per-unit", type=float, default=1.0, show_default=True, help="Output units.")
@click.option("--max-influences", type=click.IntRange(1, 16), default=4, show_default=True,
              help="Skin influences kept per vertex (the asset's elementSize).")
@click.option("--unweighted", type=click.Choice(["error", "nearest-bone"]), default="error", show_default=True,
              help="What to do with vertices that have no skin weight.")
@click.option("--parts", "parts_mode", type=click.Choice(["dominant", "any"]), default="dominant", show_default=True,
              help="dominant: a triangle goes to the bone with the largest summed weight; any: to every bone above --parts-threshold.")
@click.option("--parts-threshold", type=click.FloatRange(0, 1), default=PARTS_ANY_THRESHOLD, show_default=True,
              help="Weight a bone needs on a triangle's vertex to own it with --parts any.")
@click.option("--min-part-faces", type=click.IntRange(1), default=1, show_default=True,
              help="Bones owning fewer triangles fold into their parent's part.")
@click.option("--mesh", "meshes", multiple=True, metavar="NAME",
              help="Mesh to import (repeatable); default every mesh skinned to the skeleton, merged.")
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Frame rate of the output grid; default the source's own when its keys sit on one, else 30.")
@click.option("--source-up-axis", type=click.Choice(["Y", "Z"], case_sensitive=False), default=None,
              help="Override the up axis the reader assumes for the source.")
@click.option("--source-meters-per-unit", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Override the units the reader assumes for the source.")
@click.option("--target-faces", type=click.IntRange(min=4), default=None, metavar="N",
              help="Simplify the collision mesh to at most N triangles (a collision proxy; off by default).")
@click.option("--max-deviation", default=None, metavar="D",
              help="Simplify while the proxy stays within D of the full skinned mesh on every frame "
                   "(stage units, or D% of the model size).")
@click.option("--allow-outside-references", is_flag=True,
              help="Let the source reference files outside its own folder (absolute paths, '..'); "
                   "refused by default. Only regular files are ever read.")
@click.option("--strict", is_flag=True,
              help="Refuse (exit 1, nothing written) when the source holds anything the import does not "
                   "carry exactly (each is a 'not carried' warning otherwise).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--progress/--no-progress", default=None,
              help="Show a progress bar on stderr (default: for large inputs on a terminal).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=1, show_default=True,
              help="Several inputs: import in N parallel processes.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Several inputs: run on a Dask cluster (tcp://host:8786, or local:N; needs colossus[dask]).")
@maps_errors(input_status=1)
def import_cmd(srcs, out, up_axis, meters_per_unit, max_influences, unweighted, parts_mode, parts_threshold,
               min_part_faces, meshes, fps, source_up_axis, source_meters_per_unit, target_faces, max_deviation,
               allow_outside_references, strict, as_json, progress, jobs, scheduler):
    """Import the Blender export SRC and write the collider asset OUT.

    \b
    Stages: read, bake, weld, degenerate, orient, bind, [simplify], parts, quantize, spheres, write.
    Exit status: 0 written; 1 the input is unusable, or with --strict holds something
    not carried exactly, or the asset made of it would fail one of the validator's error
    rules (checked before it is renamed into place; nothing written); 2 usage, or an output
    that cannot be written.

    \b
    Several inputs (SRC..., directories, globs): -o is a directory and each input becomes
    DIR/<stem>.usda (<stem>.<ext>.usda where two inputs share a stem); one line per input,
    exit 1 if any failed, 130 interrupted.

    \b
    Example:
      colossus import samples/creature.glb -o creature.usda
      colossus import 'exports/*.glb' -o colliders/ --jobs 4
    """
    from colossus.pipeline.run import ImportSettings, import_asset

    settings = ImportSettings(
        up_axis=up_axis.upper(), meters_per_unit=meters_per_unit, max_influences=max_influences,
        unweighted=unweighted, parts=parts_mode, min_part_faces=min_part_faces,
        parts_threshold=parts_threshold, meshes=list(meshes), fps=fps,
        source_up_axis=source_up_axis.upper() if source_up_axis else None,
        source_meters_per_unit=source_meters_per_unit, target_faces=target_faces, max_deviation=max_deviation,
        allow_outside_references=allow_outside_references,
    )
    from colossus.pipeline.engine import is_glob
    from colossus.pipeline.stages.write import OUTPUT_EXTENSIONS
    one_file_out = out.lower().endswith(OUTPUT_EXTENSIONS) and not os.path.isdir(out)
    if len(srcs) > 1 or ((os.path.isdir(srcs[0]) or is_glob(srcs[0])) and not one_file_out):
        return _import_many(srcs, out, settings, as_json, progress, jobs, scheduler, strict)
    src = srcs[0]
    if progress is None:
        try:
            big = os.path.getsize(src) >= LARGE_INPUT_BYTES
        except OSError:
            big = False
        progress = big and sys.stderr.isatty()

    tty = sys.stderr.isatty()

    def on_stage(i, n, name):
        """A one-line bar redrawn in place on a terminal; one line per stage otherwise."""
        if not progress:
            return
        done = int(24 * i / n)
        line = f"importing [{'#' * done}{'-' * (24 - done)}] {i}/{n} {name}"
        click.echo(("\r" + line.ljust(60)) if tty else line, err=True, nl=not tty)

    result = import_asset(src, out, settings, progress=on_stage, strict=strict, check=error_rules)
    n = len(settings.stages())
    on_stage(n, n, "done")
    if progress and tty:
        click.echo("", err=True)
    if as_json:
        click.echo(json.dumps(result.summary(), indent=2, default=float))
    else:
        click.echo(format_summary(result))


def _import_many(srcs, out, settings, as_json, progress, jobs, scheduler, strict=False):
    """``colossus import A B ... -o DIR``: see :mod:`pipeline.batch`."""
    from colossus.pipeline.batch import format_import_rows, import_many
    from colossus.pipeline.stages.write import OUTPUT_EXTENSIONS

    if os.path.isfile(out) or (not os.path.isdir(out) and out.lower().endswith(OUTPUT_EXTENSIONS)):
        raise UsageError(f"-o {out}: with several inputs, -o is the output directory")
    settings.check()
    show = sys.stderr.isatty() if progress is None else progress
    try:
        rows, interrupted = import_many(srcs, out, settings, jobs=jobs, scheduler=scheduler, progress=show,
                                        strict=strict, check=error_rules)
    except OSError as exc:
        raise OutputError(f"-o {out}: {exc.strerror or exc}") from None
    if as_json:
        doc = {"imports": rows}
        if interrupted:
            doc["incomplete"] = True
        click.echo(json.dumps(doc, indent=2, default=float))
    else:
        click.echo(format_import_rows(rows, interrupted))
    for r in rows:
        if r["ok"] is False:
            click.echo(f"error: {r['source']}: {r['error']}", err=True)
    click.get_current_context().exit(interrupted_status() if interrupted else 0 if all(r["ok"] for r in rows) else 1)
