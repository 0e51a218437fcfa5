"""Render a :class:`~.document.Report` as one self-contained HTML page.

Everything is inside the file: CSS embedded, figures as ``data:`` URIs, no scripts,
no external fonts, so the page opens offline and prints cleanly (A4, tables with
repeated header rows, figures kept whole). All text is escaped by Jinja2.
"""

from __future__ import annotations

import base64

import jinja2
from markupsafe import Markup

from .document import (Figure, Heading, Item, KeyValues, Paragraph, Preformatted, Report,
                       ReportError, Status, Table, _is_bool, caption, outline)

__all__ = ["render_html"]

_CSS = """
:root { --ink: #1b1f23; --muted: #5f6670; --rule: #1b1f23; --hair: #d3d7dc;
        --pass: #1a7f37; --fail: #c62828; --error: #8e1b1b; --note: #35607f; }
* { box-sizing: border-box; }
html { background: #ffffff; }
body { margin: 0; color: var(--ink); background: #ffffff;
       font-family: "Helvetica Neue", Helvetica, Arial, "Liberation Sans", "DejaVu Sans", sans-serif;
       font-size: 15px; line-height: 1.45; overflow-wrap: break-word; }
main { max-width: 1000px; margin: 0 auto; padding: 28px 36px 56px; }
header.title { border-bottom: 2px solid var(--rule); padding-bottom: 10px; margin-bottom: 14px; }
h1 { font-size: 1.75em; margin: 0 0 4px; line-height: 1.2; }
.subtitle { font-size: 1.1em; color: var(--ink); margin: 0 0 4px; }
.date { color: var(--muted); font-size: 0.9em; margin: 0; }
h2 { font-size: 1.3em; margin: 1.8em 0 0.6em; padding-bottom: 3px;
     border-bottom: 1px solid var(--hair); }
h3 { font-size: 1.08em; margin: 1.3em 0 0.5em; }
.num-label { display: inline-block; min-width: 1.7em; color: var(--muted); }
h3 .num-label, nav.toc ol ol .num-label { min-width: 2.4em; }
p.text { margin: 0.5em 0 0.8em; white-space: pre-line; }
pre { white-space: pre-wrap; overflow-wrap: anywhere; background: #f5f6f7;
      border: 1px solid var(--hair); padding: 8px 10px; font-size: 0.82em; line-height: 1.35;
      font-family: "DejaVu Sans Mono", Menlo, Consolas, "Liberation Mono", monospace; }
nav.toc { border: 1px solid var(--hair); padding: 8px 16px 10px; margin: 14px 0 8px;
          background: #fafbfc; }
nav.toc .toc-title { font-weight: 700; margin: 0 0 4px; }
nav.toc ol { list-style: none; margin: 0; padding-left: 0; }
nav.toc ol ol { padding-left: 1.7em; font-size: 0.95em; }
nav.toc li { margin: 1px 0; }
nav.toc a { color: var(--ink); text-decoration: none; }
nav.toc a:hover { text-decoration: underline; }
.banner { border-left: 7px solid; padding: 9px 14px; margin: 14px 0; font-size: 1.02em; }
.banner .outcome { font-weight: 700; letter-spacing: 0.04em; margin-right: 0.6em; }
.banner.pass { border-color: var(--pass); background: #e8f4ec; }
.banner.pass .outcome { color: var(--pass); }
.banner.fail { border-color: var(--fail); background: #fbeaea; }
.banner.fail .outcome { color: var(--fail); }
.banner.error { border-color: var(--error); background: #f7e3e3; }
.banner.error .outcome { color: var(--error); }
.banner.note { border-color: var(--note); background: #eaf0f5; }
.banner.note .outcome { color: var(--note); }
table { border-collapse: collapse; margin: 0.3em 0 1.3em; font-size: 0.9em; width: 100%; }
table.kv { width: auto; min-width: 55%; max-width: 100%; }
caption { caption-side: top; text-align: left; font-weight: 700; padding: 0 0 5px; }
thead th { text-align: left; vertical-align: bottom; font-weight: 700; padding: 4px 8px;
           border-top: 1.5px solid var(--rule); }
thead tr:last-child th { border-bottom: 1px solid var(--rule); }
thead tr.units th { font-weight: 400; color: var(--muted); padding-top: 0; }
td { padding: 3px 8px; vertical-align: top; border-bottom: 1px solid var(--hair);
     overflow-wrap: anywhere; }
tbody tr:last-child td { border-bottom: 1.5px solid var(--rule); }
table.kv td { border-bottom: 1px solid var(--hair); }
table.kv tr:first-child td { border-top: 1.5px solid var(--rule); }
table.kv td.label { color: var(--muted); padding-right: 24px; white-space: nowrap; }
th.num, td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.num { white-space: nowrap; }
th.status, td.status { text-align: center; }
th.num + th.text, td.num + td.text, th.num + th.status, td.num + td.status { padding-left: 22px; }
span.pass { color: var(--pass); font-weight: 700; }
span.fail { color: var(--fail); font-weight: 700; }
span.na { color: var(--muted); }
figure { margin: 0.8em 0 1.4em; }
figure img { display: block; max-width: 100%; height: auto; margin: 0 auto;
             border: 1px solid var(--hair); }
figcaption { margin-top: 6px; font-size: 0.92em; text-align: center; }
figcaption .label, caption .label { font-weight: 700; }
caption .text { font-weight: 400; }
@page { size: A4; margin: 15mm 14mm; }
@media print {
  body { font-size: 10.5pt; }
  main { max-width: none; padding: 0; }
  nav.toc { background: none; }
  h2, h3, caption { break-after: avoid; page-break-after: avoid; }
  figure, .banner, pre { break-inside: avoid; page-break-inside: avoid; }
  tr { break-inside: avoid; page-break-inside: avoid; }
  thead { display: table-header-group; }
  a { color: inherit; text-decoration: none; }
}
"""

_TEMPLATE = """<!DOCTYPE html>
{%- macro banner(st) -%}
<div class="banner {{ st.outcome|lower }}" role="status"><span class="outcome">{{ st.outcome }}</span>{{ st.message }}</div>
{%- endmacro -%}
{%- macro cell(c) -%}
<td class="{{ c.cls }}">{% if c.span %}<span class="{{ c.span }}">{{ c.text }}</span>{% else %}{{ c.text }}{% endif %}</td>
{%- endmacro -%}
{%- macro label(it) -%}
<span class="label">{{ it.label }}{% if it.caption %}:</span> <span class="text">{{ it.caption }}</span>{% else %}</span>{% endif %}
{%- endmacro %}
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="workbench.report">
<title>{{ title }}</title>
<style>{{ css }}</style>
</head>
<body>
<main>
<header class="title">
<h1>{{ title }}</h1>
{% if subtitle %}<p class="subtitle">{{ subtitle }}</p>
{% endif %}<p class="date">{{ date }}</p>
</header>
{% if status %}{{ banner(status) }}
{% endif %}
{%- if sections %}
<nav class="toc">
<p class="toc-title">Contents</p>
<ol>
{% for sec in sections %}<li><a href="#{{ sec.anchor }}"><span class="num-label">{{ sec.number }}</span>{{ sec.title }}</a>
{%- if sec.subheadings %}
<ol>
{% for h in sec.subheadings %}<li><a href="#{{ h.anchor }}"><span class="num-label">{{ h.label }}</span>{{ h.text }}</a></li>
{% endfor %}</ol>
{%- endif %}</li>
{% endfor %}</ol>
</nav>
{% endif %}
{%- for sec in sections %}
<section id="{{ sec.anchor }}">
<h2><span class="num-label">{{ sec.number }}</span>{{ sec.title }}</h2>
{% for it in sec.blocks %}
{%- if it.kind == "heading" -%}
<h3 id="{{ it.anchor }}"><span class="num-label">{{ it.label }}</span>{{ it.text }}</h3>
{% elif it.kind == "paragraph" -%}
<p class="text">{{ it.text }}</p>
{% elif it.kind == "pre" -%}
<pre>{{ it.text }}</pre>
{% elif it.kind == "status" -%}
{{ banner(it) }}
{% elif it.kind == "kv" -%}
<table class="kv"><tbody>
{% for r in it.rows %}<tr><td class="label">{{ r.label }}</td>{{ cell(r.value) }}</tr>
{% endfor %}</tbody></table>
{% elif it.kind == "table" -%}
<table id="{{ it.anchor }}">
<caption>{{ label(it) }}</caption>
<thead>
<tr>{% for c in it.columns %}<th class="{{ c.cls }}" scope="col">{{ c.text }}</th>{% endfor %}</tr>
{% if it.units %}<tr class="units">{% for c in it.units %}<th class="{{ c.cls }}">{{ c.text }}</th>{% endfor %}</tr>
{% endif %}</thead>
<tbody>
{% for row in it.rows %}<tr>{% for c in row %}{{ cell(c) }}{% endfor %}</tr>
{% endfor %}</tbody>
</table>
{% elif it.kind == "figure" -%}
<figure id="{{ it.anchor }}">
<img src="data:image/png;base64,{{ it.b64 }}" width="{{ it.w }}" height="{{ it.h }}" style="width: {{ it.width_pct }}%" alt="{{ it.alt }}">
<figcaption>{{ label(it) }}</figcaption>
</figure>
{% endif %}
{%- endfor %}
</section>
{% endfor %}
</main>
</body>
</html>
"""

_ENV = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined,
                          keep_trailing_newline=True)
_PAGE = _ENV.from_string(_TEMPLATE)


def _cell(text: str, value, kind: str) -> dict:
    span = ""
    if value is None or text == "n/a":
        span = "na"
    elif _is_bool(value):
        span = "pass" if value else "fail"
    return {"text": text, "cls": kind, "span": span}


def _item(it: Item) -> dict:
    b = it.block
    if isinstance(b, Heading):
        return {"kind": "heading", "label": it.label, "anchor": it.anchor, "text": b.text}
    if isinstance(b, Paragraph):
        return {"kind": "paragraph", "text": b.text}
    if isinstance(b, Preformatted):
        return {"kind": "pre", "text": b.text}
    if isinstance(b, Status):
        return {"kind": "status", "outcome": b.outcome, "message": b.message}
    if isinstance(b, KeyValues):
        rows = [{"label": label, "value": _cell(text, None if text == "n/a" else str(text),
                                                 "value")}
                for label, text, value in b.formatted()]
        return {"kind": "kv", "rows": rows}
    if isinstance(b, Table):
        v = b.view()
        units = None
        if v.units is not None and any(v.units):
            units = [{"text": f"[{u}]" if u else "", "cls": k} for u, k in zip(v.units, v.kinds)]
        rows = [[_cell(t, x, k) for t, x, k in zip(texts, values, v.kinds)]
                for texts, values in zip(v.texts, v.values)]
        return {"kind": "table", "anchor": it.anchor, "label": it.label, "caption": b.caption,
                "columns": [{"text": c, "cls": k} for c, k in zip(v.columns, v.kinds)],
                "units": units, "rows": rows}
    if isinstance(b, Figure):
        return {"kind": "figure", "anchor": it.anchor, "label": it.label, "caption": b.caption,
                "b64": base64.b64encode(b.image).decode("ascii"),
                "w": b.pixels[0], "h": b.pixels[1],
                "width_pct": f"{100.0 * b.width:.4g}", "alt": caption(it)}
    raise ReportError(f"cannot render a {type(b).__name__} block in HTML")


def render_html(report: Report) -> str:
    """The report as one self-contained HTML page (UTF-8 text).

    Parameters
    ----------
    report : Report
        The document.

    Returns
    -------
    str
        The page: embedded CSS, figures as base64 ``data:`` URIs, no external
        resources and no scripts.
    """
    sections = []
    for sec in outline(report):
        items = []
        for it in sec.items:
            try:
                items.append(_item(it))
            except ReportError:
                raise
            except Exception as exc:
                what = it.label or type(it.block).__name__
                raise ReportError(f"HTML: section {sec.number} {sec.title!r}, {what}: "
                                  f"{type(exc).__name__}: {exc}") from exc
        sections.append({"number": sec.number, "title": sec.title, "anchor": sec.anchor,
                         "subheadings": [{"label": h.label, "anchor": h.anchor,
                                          "text": h.block.text} for h in sec.subheadings],
                         "blocks": items})
    status = None
    if report.status is not None:
        status = {"outcome": report.status.outcome, "message": report.status.message}
    return _PAGE.render(title=report.title, subtitle=report.subtitle, date=report.shown_date(),
                        status=status, sections=sections, css=Markup(_CSS))
