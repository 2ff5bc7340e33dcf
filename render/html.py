"""The HTML reporter (``colossus validate --format html -o report.html``).

One self-contained page per run, built from the same list of
:class:`~validators.findings.AssetReport` as the text, JSON and JUnit reporters: one
``<section class="asset">`` per asset with its findings, what the frame proof checked, a picture
of the worst failing frame (the failing part red, its offending vertices marked; the bind pose
when nothing fails) and a plot of every part's sphere slack (radius minus the farthest vertex
distance, stage units) over the frames of each clip.  Images are embedded as base64 PNG, so the
page is one file with no outside references.

Pictures need the asset on disk (read again here) and an OpenGL context; when either is
missing the section says why in place of the picture, and the report is still written.
"""

from __future__ import annotations

import base64
import html
import io

from colossus.validators.findings import SEVERITY_RANK, summary_line

#: Codes whose findings say the file could not be read at all (no pictures then).
UNREADABLE = ("COL001", "COL003")

CSS = """
body{font:14px/1.4 system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:24px;color:#222;
 max-width:1200px}
h1{font-size:22px;margin:0 0 4px} h2{font-size:17px;margin:0 0 8px;word-break:break-all}
.summary{color:#555;margin-bottom:16px}
section.asset{border:1px solid #ddd;border-left:6px solid #3a3;border-radius:4px;padding:12px 16px;
 margin:16px 0}
section.asset.fail{border-left-color:#d22}
.badge{display:inline-block;padding:1px 8px;border-radius:10px;color:#fff;font-size:12px;
 vertical-align:middle;margin-left:6px} .badge.pass{background:#3a3} .badge.fail{background:#d22}
table{border-collapse:collapse;width:100%;margin:8px 0} th,td{text-align:left;padding:3px 8px;
 border-bottom:1px solid #eee;vertical-align:top} th{background:#f6f6f6}
td.sev-error{color:#c00;font-weight:600} td.sev-warning{color:#b60} td.sev-info{color:#467}
td.where{font-family:ui-monospace,Menlo,monospace;font-size:12px;color:#555}
figure{display:inline-block;margin:8px 16px 8px 0;vertical-align:top} img{max-width:100%;
 border:1px solid #eee} figcaption{font-size:12px;color:#555;max-width:640px}
ul.checked{margin:4px 0 8px;color:#444;font-size:13px} .note{color:#888;font-style:italic}
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _img(png: bytes, alt: str) -> str:
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}">'


def worst_frame(report):
    """The finding the picture shows: the worst error finding located at a clip time (the frame
    proof's COL403), else a bind-pose containment error (COL402), else None."""
    timed = [f for f in report.findings if f.severity == "error" and f.clip is not None and f.time is not None]
    if timed:
        return max(timed, key=lambda f: f.sort_key)
    bind = [f for f in report.findings if f.severity == "error" and f.code == "COL402"]
    return max(bind, key=lambda f: f.sort_key) if bind else None


def slack_plot(asset, dpi: int = 80) -> bytes:
    """PNG: one panel per clip, each part's slack (radius - farthest vertex distance) per frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from colossus.render.draw import part_colors, slack_series

    clips = [c for c in asset.clips if len(c.times)]
    P = len(asset.part_joints)
    colors = part_colors(P)
    fig = Figure(figsize=(8.0, 2.6 * max(1, len(clips)) + 0.3), dpi=dpi)
    FigureCanvasAgg(fig)
    tcps = float(asset.stage.GetTimeCodesPerSecond()) or 24.0
    for i, c in enumerate(clips):
        ax = fig.add_subplot(len(clips), 1, i + 1)
        times, slack = slack_series(asset, c.name)
        x = (times - times[0]) / tcps
        for p in range(P):
            bad = slack[:, p].min() < 0
            name = asset.part_joints[p].rsplit("/", 1)[-1]
            ax.plot(x, slack[:, p], color=(0.86, 0.06, 0.06) if bad else colors[p], lw=2.2 if bad else 1.2,
                    marker="." if len(x) < 3 else None, label=f"{p} {name}" + (" (fails)" if bad else ""))
        lo = min(0.0, float(slack.min()))
        ax.axhline(0.0, color="k", lw=0.8, ls="--")
        if lo < 0:
            ax.axhspan(lo * 1.1, 0, color=(1, 0.85, 0.85), zorder=0)
        ax.set_title(f"clip {c.name}: sphere slack per part ({len(times)} frames)", fontsize=10)
        ax.set_ylabel("radius - farthest", fontsize=9)
        ax.tick_params(labelsize=8)
        if i == len(clips) - 1:
            ax.set_xlabel("seconds into the clip", fontsize=9)
        if P <= 24:
            ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), ncol=1 if P <= 12 else 2,
                      frameon=False)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _pictures(report, size=(640, 480)) -> str:
    """The picture and slack plot of one asset, or a note saying why there are none."""
    if any(f.code in UNREADABLE for f in report.findings):
        return '<p class="note">no pictures: the asset could not be read</p>'
    from colossus.render.draw import RenderError, png_bytes, pose_at, render_image
    from colossus.validators.summary import AssetError, one_line, open_asset

    try:
        asset = open_asset(report.path)
        ok, why = asset.ready("spheres")
        if not ok:
            return f'<p class="note">no pictures: {_e(why)}</p>'
    except AssetError as e:
        return f'<p class="note">no pictures: {_e(e)}</p>'
    out = []
    f = worst_frame(report)
    try:
        if f is not None and f.clip is not None:
            pose = pose_at(asset, f.clip, f.time)
            caption = f"worst failing frame ({f.code}): {f.message}"
        else:
            pose = pose_at(asset)
            caption = (f"bind pose ({f.code}): {f.message}" if f is not None
                       else "bind pose: no failing frame; each part's sphere in the part's colour")
        png = png_bytes(render_image(asset, pose, size))
        out.append(f'<figure class="frame">{_img(png, pose.label)}<figcaption>{_e(caption)}</figcaption></figure>')
    except RenderError as e:
        out.append(f'<p class="note">no picture: {_e(e)}</p>')
    except Exception as e:  # no OpenGL context on this machine, ...
        out.append(f'<p class="note">no picture (renderer unavailable): {_e(one_line(e))}</p>')
    if asset.ready("proof")[0]:
        try:
            png = slack_plot(asset)
            out.append(f'<figure class="slack">{_img(png, "sphere slack per part over each clip")}'
                       '<figcaption>sphere slack: world radius minus the distance of the part\'s farthest '
                       'skinned vertex, per frame (below 0: a vertex is outside)</figcaption></figure>')
        except Exception as e:
            out.append(f'<p class="note">no slack plot: {_e(one_line(e))}</p>')
    return "\n".join(out)


def _section(i, r, pictures) -> str:
    errors = sum(f.severity == "error" for f in r.findings)
    warnings = sum(f.severity == "warning" for f in r.findings)
    state = "pass" if r.passed else "fail"
    out = [f'<section class="asset {state}" id="asset-{i}" data-path="{_e(r.path)}">',
           f'<h2>{_e(r.path)}<span class="badge {state}">{state.upper()}</span></h2>',
           f'<p>{errors} errors, {warnings} warnings, {len(r.findings)} findings'
           + "".join(f", {k} {_e(r.stats[k])}" for k in ("vertices", "faces", "joints", "parts", "clips", "frames")
                     if k in r.stats) + "</p>"]
    if r.findings:
        out.append("<table class=\"findings\"><tr><th>code</th><th>severity</th><th>rule</th><th>message</th>"
                   "<th>where</th></tr>")
        for f in sorted(r.findings, key=lambda f: (SEVERITY_RANK.get(f.severity, 9), f.code, -f.sort_key)):
            out.append(f'<tr><td>{_e(f.code)}</td><td class="sev-{_e(f.severity)}">{_e(f.severity)}</td>'
                       f'<td>{_e(f.rule)}</td><td>{_e(f.message)}</td><td class="where">{_e(" ".join(x for x in (f.where(), f"prim={f.prim_path}") if x))}</td></tr>')
        out.append("</table>")
    fpp = r.stats.get("frameproof") or {}
    items = [f"checked: {c}" for c in fpp.get("checked", [])] + [f"not checked: {c}" for c in fpp.get("not_checked", [])]
    items += [f"skipped {code}: {why}" for code, why in sorted(r.skipped.items())]
    if items:
        out.append('<ul class="checked">' + "".join(f"<li>{_e(x)}</li>" for x in items) + "</ul>")
    if pictures:
        out.append(_pictures(r))
    out.append("</section>")
    return "\n".join(out)


def format_html(reports, pictures: bool = True, unchecked=None) -> str:
    """One self-contained HTML page for a run (``pictures=False``: findings only, no rendering);
    ``unchecked`` (paths, given when the run was interrupted) puts an INCOMPLETE banner on top."""
    body = [f"<h1>colossus validate</h1><p class=\"summary\">{_e(summary_line(reports))}</p>"]
    body += [_section(i, r, pictures) for i, r in enumerate(reports)]
    if unchecked is not None:
        items = "".join(f"<li>{_e(p)}</li>" for p in unchecked)
        body.insert(0, f'<div class="incomplete" style="border:2px solid #c00;padding:.5em;margin:.5em 0">'
                       f"<strong>INCOMPLETE</strong>: the run was interrupted; {len(unchecked)} asset(s) not checked"
                       f"<ul>{items}</ul></div>")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>colossus validate: {_e(summary_line(reports))}</title><style>{CSS}</style></head>\n<body>\n"
            + "\n".join(body) + "\n</body></html>\n")


__all__ = ["format_html", "slack_plot", "worst_frame"]
