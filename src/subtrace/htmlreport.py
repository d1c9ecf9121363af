"""Self-contained HTML reports: ``subtrace compare --html``, the golden plugin's session page
(:mod:`subtrace.testing.plugin`) and ``subtrace sweep --html``.

One page per run, readable offline as a CI artefact: every image is inlined as a
``data:image/png;base64`` URI (PNG encoded here, :func:`png_bytes`), the style sheet and the
few lines of script (the reference / new slider and its toggle) are in the page, and nothing
is fetched from the network. Per compared image the page shows the new render and the
reference under a slider, the difference |A - B|, the heat map (each pixel's largest error
over its group's fail threshold, ids left out) and a heat map per group that differs, each
with a colour key in its units, the ids map (pixels whose level, patch or object id changed)
with its key and count, and the group table with the thresholds and FLIP where computed.
A sweep's page (:func:`sweep_page`) holds its table, its plots and, per scene, the reference
and each tolerance's render beside its refinement-level heat map with the levels' key.

Verdicts are in the markup for machines too: each image's ``<section class="image">`` has
``data-name`` and ``data-verdict``, each group row ``<tr data-group=... data-verdict=...>``,
each key ``class="key"``.
"""

from __future__ import annotations

import base64
import html
import math
import os
import struct
import zlib

import numpy as np

from subtrace.compare import format_value
from subtrace.runtime.atomic import write_text
from subtrace.version import VERSION

# images narrower than this are shown enlarged by a whole factor (pixels stay square and
# sharp); wider ones at most MAX_SHOW_PX wide
MIN_SHOW_PX = 320
MAX_SHOW_PX = 480
PLOT_SHOW = {"error_vs_tolerance.png": 620}  # displayed widths of the sweep's plots (else 420)
DIFF_GAIN = 10.0  # the difference |A - B| is shown times this (small errors stay visible)
# the heat map's ramp (subtrace.compare.heat_map): error / fail threshold at each stop
HEAT_STOPS = (0.0, 0.5, 1.0, 2.0)
# units of each group's per-pixel error (subtrace.compare's module comment)
UNITS = {
    "colour": "max |ΔR|,|ΔG|,|ΔB| (linear)",
    "coverage": "pixels with the surface in one image only",
    "depth": "|ΔZ| / Z (relative)",
    "normals": "angle (degrees)",
    "position": "|ΔP| / Z (relative)",
}

STYLE = """
:root { --fg: #1d2330; --muted: #5b6475; --line: #d9dde5; --bg: #f6f7f9; --card: #fff;
  --pass: #1e7d3c; --warn: #a86500; --fail: #b3261e; }
* { box-sizing: border-box; }
body { margin: 0; font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif;
  color: var(--fg); background: var(--bg); }
header { padding: 18px 28px 10px; background: var(--card); border-bottom: 1px solid var(--line); }
h1 { font-size: 20px; margin: 0 0 2px; } h2 { font-size: 17px; margin: 0 0 6px; }
h3 { font-size: 14px; margin: 14px 0 6px; }
.sub { color: var(--muted); margin: 0 0 10px; }
main { padding: 18px 28px 40px; }
section { background: var(--card); border: 1px solid var(--line); border-radius: 8px;
  padding: 16px 18px; margin: 0 0 18px; }
.paths { color: var(--muted); font-size: 12px; word-break: break-all; margin: 0 0 10px; }
.row { display: flex; flex-wrap: wrap; gap: 16px; align-items: flex-start; }
figure { margin: 0; }
figcaption { font-size: 12px; color: var(--muted); margin-top: 4px; max-width: 480px; }
img { display: block; image-rendering: pixelated; border: 1px solid var(--line);
  background: #000; }
.swipe { position: relative; }
.swipe img.over { position: absolute; left: 0; top: 0; }
.swipe input { width: 100%; margin: 4px 0 0; }
button { font: inherit; font-size: 12px; padding: 2px 10px; border: 1px solid var(--line);
  border-radius: 4px; background: var(--bg); cursor: pointer; }
.verdict { display: inline-block; padding: 0 8px; border-radius: 10px; font-size: 12px;
  font-weight: 600; color: #fff; vertical-align: 2px; }
.verdict.pass { background: var(--pass); } .verdict.warn { background: var(--warn); }
.verdict.fail { background: var(--fail); } .verdict.none { background: var(--muted); }
table { border-collapse: collapse; font-size: 12.5px; margin-top: 12px; }
th, td { padding: 3px 10px 3px 0; text-align: left; border-bottom: 1px solid var(--line);
  vertical-align: top; }
th { color: var(--muted); font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr[data-verdict="fail"] td:nth-child(2) { color: var(--fail); font-weight: 600; }
tr[data-verdict="warn"] td:nth-child(2) { color: var(--warn); font-weight: 600; }
.key { font-size: 11px; color: var(--muted); margin-top: 4px; }
.key .bar { height: 10px; border: 1px solid var(--line); }
.key .ticks { position: relative; height: 14px; }
.key .ticks span { position: absolute; transform: translateX(-50%); white-space: nowrap; }
.key .ticks span:first-child { transform: none; }
.key .ticks span:last-child { transform: translateX(-100%); }
.key .swatch { display: inline-block; width: 10px; height: 10px; margin: 0 4px 0 8px;
  border: 1px solid var(--line); vertical-align: -1px; }
.key .swatch:first-child { margin-left: 0; }
.note { color: var(--muted); }
"""

SCRIPT = """
function swipe(r) {
  r.parentNode.querySelector('img.over').style.clipPath = 'inset(0 ' + (100 - r.value) + '% 0 0)';
}
function toggleView(b) {
  var r = b.closest('figure').querySelector('.swipe input');
  r.value = r.value > 50 ? 0 : 100; swipe(r);
  b.textContent = r.value > 50 ? 'show reference' : 'show new';
}
"""


def png_bytes(rgb_linear) -> bytes:
    """(H,W,3) linear RGB -> the bytes of an 8-bit sRGB PNG (values clipped to [0, 1];
    :func:`subtrace.io.exr.srgb8`'s codes), zlib level 6, no filter."""
    from subtrace.io.exr import srgb8

    pixels = srgb8(rgb_linear)
    height, width, _ = pixels.shape
    raw = np.concatenate([np.zeros((height, 1), np.uint8), pixels.reshape(height, -1)], axis=1)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + chunk(b"IEND", b""))


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _show_width(width: int) -> int:
    """Displayed width in CSS pixels of an image ``width`` pixels wide."""
    if width < MIN_SHOW_PX:
        return width * math.ceil(MIN_SHOW_PX / width)
    return min(width, MAX_SHOW_PX)


def _img(png: bytes, width: int, alt: str, cls: str = "", style: str = "") -> str:
    c = f' class="{cls}"' if cls else ""
    return (f'<img{c} src="{data_uri(png)}" alt="{html.escape(alt)}" '
            f'style="width:{_show_width(width)}px;{style}">')


def _figure(body: str, caption: str, key: str = "", width: int | None = None) -> str:
    style = f' style="width:{_show_width(width)}px"' if width else ""
    return f"<figure{style}>{body}{key}<figcaption>{caption}</figcaption></figure>"


def _hex(rgb_linear) -> str:
    from subtrace.io.exr import srgb8

    r, g, b = srgb8(np.asarray(rgb_linear, dtype=np.float64).reshape(1, 1, 3))[0, 0]
    return f"#{r:02x}{g:02x}{b:02x}"


def _number(v: float) -> str:
    return "0" if v == 0 else f"{v:.3g}"


def ramp_key(unit: str, fail: float | None = None) -> str:
    """The heat map's colour key: the ramp from 0 to twice the fail threshold with ticks in
    ``unit`` (the group's, for ``fail`` a number; "× fail threshold" for None)."""
    from subtrace.compare import heat_map

    top = HEAT_STOPS[-1]
    stops = ", ".join(f"{_hex(heat_map(np.array([[h]]))[0, 0])} {100 * h / top:g}%"
                      for h in HEAT_STOPS)
    ticks = []
    for h in HEAT_STOPS:
        label = f"{_number(h)}×" if fail is None else _number(h * fail)
        if h == 1.0:
            label += " fail"
        if h == top:
            label = "≥ " + label
        ticks.append(f'<span style="left:{100 * h / top:g}%">{html.escape(label)}</span>')
    return (f'<div class="key heat-key" data-unit="{html.escape(unit)}">'
            f'<div class="bar" style="background:linear-gradient(to right, {stops})"></div>'
            f'<div class="ticks">{"".join(ticks)}</div><div>{html.escape(unit)}</div></div>')


def swatch_key(items, title: str = "") -> str:
    """A key of colour swatches: ``items`` (linear RGB or '#rrggbb', label) pairs."""
    parts = []
    for colour, label in items:
        hexa = colour if isinstance(colour, str) else _hex(colour)
        parts.append(f'<span class="swatch" style="background:{hexa}"></span>'
                     f"{html.escape(label)}")
    head = f"<div>{html.escape(title)}</div>" if title else ""
    return f'<div class="key swatch-key">{"".join(parts)}{head}</div>'


def _verdict(v: str | None) -> str:
    v = v or "none"
    return f'<span class="verdict {v}">{html.escape(v.upper())}</span>'


def comparison_section(comparison, name: str, label_a: str, label_b: str,
                       anchor: str, note: str = "") -> str:
    """One compared image: pictures with keys, then the group table (module comment).
    ``label_a``: the new image (A), ``label_b``: the reference (B)."""
    from subtrace.compare import IDS_COLOURS, heat_map, ids_map

    c = comparison
    w = c.width
    figures = []
    if c.rgb is not None:
        new, ref = (png_bytes(x) for x in c.rgb)
        swipe = (f'<div class="swipe">{_img(ref, w, "reference", "under")}'
                 f'{_img(new, w, "new", "over", "clip-path:inset(0 50% 0 0)")}'
                 '<input type="range" min="0" max="100" value="50" oninput="swipe(this)" '
                 'aria-label="new | reference"></div>')
        figures.append(_figure(
            swipe + '<button type="button" onclick="toggleView(this)">show new</button>',
            "new (left of the line) and reference (right): drag the slider or toggle",
            width=w))
        diff = np.abs(c.rgb[0].astype(np.float64) - c.rgb[1]) * DIFF_GAIN
        figures.append(_figure(
            _img(png_bytes(np.nan_to_num(diff, nan=1.0)), w, "difference"),
            f"difference |A − B| × {DIFF_GAIN:g}",
            ramp_key_grey(f"|ΔRGB| (linear), white ≥ {1 / DIFF_GAIN:g}"), width=w))
    heat_groups = [g for g in c.groups if g != "ids"]
    if heat_groups:
        figures.append(_figure(
            _img(png_bytes(heat_map(c.heat())), w, "heat map"),
            "heat map: each pixel's largest error over its group's fail threshold ("
            + ", ".join(heat_groups) + "; ids are not in it)",
            ramp_key("error / the group's fail threshold"), width=w))
    for group in heat_groups:
        g = c.groups[group]
        if g.max_error > 0:
            figures.append(_figure(
                _img(png_bytes(heat_map(c.heat(group))), w, f"{group} heat map"),
                f"{group}: {g.n_fail} px above fail, {g.n_warn} above warn",
                ramp_key(UNITS[group], g.thresholds.fail), width=w))
    changed = c.ids_changed()
    if changed is not None:
        count = int(changed.sum())
        figures.append(_figure(
            _img(png_bytes(ids_map(changed, c.covered)), w, "ids map"),
            f"ids: {count} px whose level, patch or object id changed",
            swatch_key([(IDS_COLOURS["changed"], f"changed ({count} px)"),
                        (IDS_COLOURS["same"], "same"),
                        ((0.0, 0.0, 0.0), "no surface in both")]), width=w))
    rows = ["<tr><th>group</th><th>verdict</th><th>pixels</th><th>&gt; warn</th>"
            "<th>&gt; fail</th><th>max</th><th>warn / fail</th><th>warn % / fail %</th>"
            "<th>metrics</th></tr>"]
    for g in c.groups.values():
        t = g.thresholds
        metrics = ", ".join(f"{k} {format_value(v)}" for k, v in g.metrics.items())
        hard = "" if math.isinf(t.hardfail) else f", hard {_number(t.hardfail)}"
        rows.append(
            f'<tr data-group="{g.name}" data-verdict="{g.verdict}"><td>{g.name}</td>'
            f"<td>{g.verdict.upper()}</td><td class=num>{g.pixels}</td>"
            f"<td class=num>{g.n_warn}</td><td class=num>{g.n_fail}</td>"
            f"<td class=num>{format_value(g.max_error)}</td>"
            f"<td>{_number(t.warn)} / {_number(t.fail)}{hard}</td>"
            f"<td>{_number(t.warnpercent)} / {_number(t.failpercent)}</td>"
            f"<td>{html.escape(metrics)}</td></tr>")
    flip = c.groups["colour"].metrics.get("mean_flip") if "colour" in c.groups else None
    flip_line = (f'<p class="flip">mean FLIP (LDR, reference B): {flip:.4g}</p>'
                 if flip is not None else "")
    note_line = f'<p class="note">{html.escape(note)}</p>' if note else ""
    return (f'<section class="image" id="{html.escape(anchor)}" data-name="{html.escape(name)}"'
            f' data-verdict="{c.verdict}"><h2>{html.escape(name)} {_verdict(c.verdict)}</h2>'
            f'<p class="paths">A (new): {html.escape(label_a)}<br>B (reference): '
            f'{html.escape(label_b)} · {c.width}×{c.height}</p>{note_line}'
            f'<div class="row">{"".join(figures)}</div>'
            f'<table class="groups">{"".join(rows)}</table>{flip_line}</section>')


def ramp_key_grey(unit: str) -> str:
    """The key of the difference image: black to white."""
    return (f'<div class="key diff-key" data-unit="{html.escape(unit)}"><div class="bar" '
            'style="background:linear-gradient(to right, #000, #fff)"></div>'
            f"<div>{html.escape(unit)}</div></div>")


def note_section(name: str, verdict: str | None, note: str, anchor: str) -> str:
    """An image that was not compared (a golden written, a mismatch): its name and why."""
    v = verdict or "none"
    return (f'<section class="image" id="{html.escape(anchor)}" data-name="{html.escape(name)}"'
            f' data-verdict="{v}"><h2>{html.escape(name)} {_verdict(verdict)}</h2>'
            f'<p class="note">{html.escape(note)}</p></section>')


def page(title: str, subtitle: str, summary: str, sections) -> str:
    """The whole page around ``sections`` (HTML strings)."""
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<meta name=\"viewport\" content=\"width=device-width\"><title>{html.escape(title)}"
        f"</title><style>{STYLE}</style><script>{SCRIPT}</script></head><body>"
        f"<header><h1>{html.escape(title)}</h1><p class=\"sub\">{html.escape(subtitle)}</p>"
        f"{summary}</header><main>{''.join(sections)}</main></body></html>\n"
    )


def compare_page(entries, title: str = "subtrace compare") -> str:
    """The page of compared images. ``entries``: dicts with ``name``, ``comparison`` (or
    None), ``a``, ``b`` (labels of the new image and the reference), optional ``verdict``
    and ``note`` (for an entry not compared)."""
    sections, rows = [], []
    counts: dict = {}
    for k, e in enumerate(entries):
        anchor = f"image-{k}"
        c = e.get("comparison")
        verdict = c.verdict if c is not None else e.get("verdict")
        counts[verdict or e.get("note", "")] = counts.get(verdict or e.get("note", ""), 0) + 1
        if c is not None:
            sections.append(comparison_section(c, e["name"], e["a"], e["b"], anchor,
                                               e.get("note", "")))
            worst = [g.name for g in c.groups.values() if g.verdict == c.verdict
                     and c.verdict != "pass"]
            detail = ", ".join(worst) or "all groups pass"
        else:
            sections.append(note_section(e["name"], verdict, e.get("note", ""), anchor))
            detail = e.get("note", "")
        rows.append(f'<tr data-name="{html.escape(e["name"])}" data-verdict="{verdict or "none"}">'
                    f'<td><a href="#{anchor}">{html.escape(e["name"])}</a></td>'
                    f"<td>{_verdict(verdict)}</td><td>{html.escape(detail)}</td></tr>")
    line = ", ".join(f"{n} {k}" for k, n in counts.items())
    summary = (f'<table class="summary"><tr><th>image</th><th>verdict</th><th>groups</th></tr>'
               f'{"".join(rows)}</table>')
    count = f"{len(entries)} image" + ("" if len(entries) == 1 else "s")
    return page(title, f"{count}: {line} · subtrace {VERSION}", summary, sections)


def write_page(path, text: str) -> None:
    """Write a page (atomically, :mod:`subtrace.runtime.atomic`)."""
    write_text(path, text)


def sweep_page(records, output_dir, title: str = "subtrace sweep") -> str:
    """The page of a sweep written to ``output_dir``: the table, the plots (the PNGs there),
    and per scene each tolerance's render and refinement-level heat map with its key."""
    from subtrace.io.exr import read_exr
    from subtrace.sweep.plot import LEVEL_COLOURS, PLOTS

    def file_img(rel: str, alt: str, width: int | None = None, css: str = "") -> str:
        with open(os.path.join(output_dir, rel), "rb") as f:
            png = f.read()
        style = f"width:{_show_width(width)}px" if width else css
        return f'<img src="{data_uri(png)}" alt="{html.escape(alt)}" style="{style}">'

    # format_table's columns (subtrace.sweep.report)
    head = ("scene", "tol px", "total s", "refine s", "trace s", "peak MiB", "refined",
            "micro-tris", "depth", "dZ mean px", "dZ max px", "N mean °", "cov", "RMSE",
            "FLIP")
    g = lambda v, p=3: "n/a" if v is None else f"{v:.{p}g}"  # noqa: E731
    rows = ["<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
    for r in records:
        cells = (r.scene, f"{r.tolerance_px:g}", f"{r.time_total_s:.3f}",
                 f"{r.time_refine_s:.3f}", f"{r.time_trace_s:.3f}",
                 "n/a" if r.peak_memory_mb is None else f"{r.peak_memory_mb:.1f}",
                 f"{r.patches_refined}/{r.patches}", str(r.micro_triangles), str(r.max_depth),
                 g(r.depth_err_px_mean), g(r.depth_err_px_max), g(r.normal_err_mean_deg),
                 str(r.coverage_mismatches), g(r.colour_rmse), g(r.flip_mean))
        rows.append(f'<tr data-scene="{html.escape(r.scene)}">' + "".join(
            f"<td{' class=num' if k else ''}>{html.escape(x)}</td>"
            for k, x in enumerate(cells)) + "</tr>")
    sections = [f'<section class="table"><h2>measurements</h2><table class="sweep">'
                f'{"".join(rows)}</table><p class="note">times: medians of the repeats; '
                "errors against the reference render; dZ in pixel footprints, N in degrees, "
                "cov: coverage mismatches (pixels)</p></section>"]
    # the plots at about two thirds of their size (matplotlib's 100 dpi): two or three a row
    plots = [_figure(file_img(name, name, css=f"width:{PLOT_SHOW.get(name, 420)}px;"
                              "max-width:100%;image-rendering:auto;background:#fff"),
                     html.escape(what))
             for name, what in PLOTS.items() if os.path.isfile(os.path.join(output_dir, name))]
    sections.append(f'<section class="plots"><h2>plots</h2><div class="row">{"".join(plots)}'
                    "</div></section>")
    levels = [(c, f"{k}{'+' if k == len(LEVEL_COLOURS) - 1 else ''}")
              for k, c in enumerate(LEVEL_COLOURS)] + [("#000000", "no surface")]
    key = swatch_key(levels, "refinement level of each pixel's hit")
    by_scene: dict = {}
    for r in records:
        by_scene.setdefault(r.scene, []).append(r)
    for scene, recs in by_scene.items():
        figures = []
        ref = os.path.join(output_dir, scene, "reference.exr")
        if os.path.isfile(ref):
            ch = read_exr(ref)[0]
            rgb = np.stack([ch[c] for c in "RGB"], axis=-1)
            figures.append(_figure(_img(png_bytes(rgb), rgb.shape[1], "reference"),
                                   f"reference ({_number(recs[0].reference_tolerance_px)} px)",
                                   width=rgb.shape[1]))
        for r in recs:
            if not r.exr:
                continue
            ch = read_exr(os.path.join(output_dir, r.exr))[0]
            rgb = np.stack([ch[c] for c in "RGB"], axis=-1)
            body = _img(png_bytes(rgb), r.width, f"render at {r.tolerance_px:g} px")
            if r.levels_png:
                body += file_img(r.levels_png, f"levels at {r.tolerance_px:g} px", r.width)
            figures.append(_figure(body, f"{r.tolerance_px:g} px: render and refinement "
                                   f"levels (deepest {r.max_depth})", key, width=r.width))
        sections.append(f'<section class="scene" data-scene="{html.escape(scene)}"><h2>'
                        f'{html.escape(scene)}</h2><div class="row">{"".join(figures)}</div>'
                        "</section>")
    scenes = ", ".join(by_scene)
    plural = "" if len(by_scene) == 1 else "s"
    return page(title, f"{len(by_scene)} scene{plural} ({scenes}), "
                f"{len({r.tolerance_px for r in records})} tolerances · subtrace {VERSION}",
                "", sections)


