"""``colossus render PATH -o FILE.png|.gif``: a picture of the collider and its part spheres (thin
layer over :mod:`validators.render`).

Exit status (the contract): 0 written; 2 the asset cannot be read or drawn, an unknown clip,
usage, or this machine cannot draw (no OpenGL context: VTK's own message); one line on stderr,
no traceback.
"""

from __future__ import annotations

import click

from colossus.cli._errors import maps_errors, missing_extra
from colossus.runtime.errors import ColossusError, one_line

SUFFIXES = (".png", ".gif")


@click.command("render")
@click.argument("path", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, writable=True),
              help="FILE.png (one pose) or FILE.gif (a whole clip).")
@click.option("--clip", help="Clip to draw (default: the bind pose for .png, the first clip for .gif).")
@click.option("--time", "time_", type=float,
              help=".png: time code within --clip (default its first frame; implies the first clip).")
@click.option("--size", default=None, metavar="WxH",
              help="Image size in pixels [800x600 for .png, 480x360 for .gif].")
@click.option("--max-frames", type=click.IntRange(min=1, max=1000), default=60, show_default=True,
              help=".gif: frames are subsampled evenly to at most this many.")
@click.option("--source", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Also draw the full mesh of FILE (the export a proxy was made from) faintly behind the collider.")
@maps_errors(input_status=2)
def render_cmd(path, output, clip, time_, size, max_frames, source):
    """Render the collision mesh of PATH with every part's sphere drawn translucent in the part's
    colour.  A part whose sphere does not hold its vertices on the pose drawn is red, and its
    offending vertices are marked in yellow.  With --source, the full skinned mesh of the export
    (imported with the asset's own settings, posed by the asset's joints) is drawn faint grey
    behind it, so the fit of a simplified proxy shows."""
    from colossus.render.draw import RenderError, parse_size, render_gif, render_png, source_mesh
    from colossus.validators.summary import open_asset

    suffix = output[output.rfind("."):].lower() if "." in output else ""
    if suffix not in SUFFIXES:
        raise click.BadParameter(f"expected a .png or .gif file name, got {output!r}", param_hint="'-o'")
    if suffix == ".gif" and time_ is not None:
        raise click.BadParameter("a .gif draws the whole clip; --time is for .png", param_hint="'--time'")
    try:
        wh = parse_size(size or ("800x600" if suffix == ".png" else "480x360"))
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="'--size'")
    try:
        asset = open_asset(path)
        full = None
        if source is not None:
            from colossus.render.draw import check_drawable

            check_drawable(asset)
            full = source_mesh(asset, source)
        if suffix == ".png":
            if clip is None and time_ is not None:
                if not asset.clips:
                    raise RenderError(f"{path}: has no clips (--time needs one)")
                clip = asset.clips[0].name
            pose = render_png(asset, output, clip=clip, time=time_, size=wh, source=full)
            what = pose.label
            failing = int(pose.failing.sum())
        else:
            ps = render_gif(asset, output, clip=clip, size=wh, max_frames=max_frames, source=full)
            what = f"{ps[0].clip}, {len(ps)} frames"
            failing = sum(bool(p.failing.any()) for p in ps)
    except ColossusError:
        raise
    except ModuleNotFoundError as e:  # an install without the render extra
        err = missing_extra(e, "render")
        if err is None:
            raise RenderError(f"could not draw on this machine: {one_line(e)}") from None
        raise err from None
    except Exception as e:  # the renderer itself (no OpenGL context, ...): the contract's status 2
        raise RenderError(f"could not draw on this machine: {one_line(e)}") from None
    unit = "frame" if suffix == ".gif" else "part"
    note = f" ({failing} {unit}{'s' if failing > 1 else ''} with a failing sphere)" if failing else ""
    click.echo(f"colossus render {path} -> {output} [{what}]{note}")
