"""A report as a list of blocks, rendered twice: a self-contained HTML page and Markdown.

Sections build :class:`Block` lists (headings, paragraphs, tables, figures, copyable code); :func:`render_html`
inlines every figure as a ``data:image/png`` URI and every style and script in the page (no network request,
opens offline), :func:`render_markdown` writes the same content as Markdown with the figures as PNG files
beside it. Nothing here knows about optipose's results.
"""

from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field
from pathlib import Path

from optipose.files import write_bytes

__all__ = ["Block", "Heading", "Paragraph", "Table", "Figure", "Code", "Details", "render_html", "render_markdown"]


@dataclass(frozen=True)
class Heading:
    text: str
    level: int = 2


@dataclass(frozen=True)
class Paragraph:
    text: str
    css: str = ""  # e.g. "verdict good", "verdict bad", "note"


@dataclass(frozen=True)
class Table:
    """header (n,) strings, rows of n cells; ``links`` maps (row, column) to an href (study tables)."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    sortable: bool = False
    links: dict = field(default_factory=dict)
    numeric: tuple[bool, ...] = ()  # right-aligned columns (default: every column but the first)
    anchor: str = ""  # the table's id, for links to it and for scripts and tests to find it


@dataclass(frozen=True)
class Figure:
    """A PNG (bytes); ``name`` is its file name beside report.md."""

    png: bytes
    name: str
    caption: str


@dataclass(frozen=True)
class Code:
    """Text to copy (a pose for a robot program): shown preformatted with a copy button."""

    text: str
    title: str = ""


@dataclass(frozen=True)
class Details:
    """Blocks folded under a one-line summary (a study's trial, all of its columns); ``anchor``: its id, a
    link to ``#anchor`` unfolds it."""

    summary: str
    blocks: tuple
    anchor: str = ""


Block = Heading | Paragraph | Table | Figure | Code | Details

_CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;background:#f4f5f7;color:#1d232b}
main{max-width:1180px;margin:0 auto;padding:24px 32px 64px;background:#fff;min-height:100vh}
h1{font-size:26px;margin:0 0 4px}h2{font-size:20px;margin:36px 0 10px;border-bottom:2px solid #e3e6ea;padding-bottom:4px}
h3{font-size:16px;margin:22px 0 8px}p{margin:6px 0}
.verdict{font-size:16px;padding:8px 12px;border-radius:6px;margin:6px 0;border-left:6px solid}
.good{background:#e8f6ec;border-color:#2e9d4f}.info{background:#eef3fb;border-color:#3b6fb6}.bad{background:#fdecea;border-color:#c8362b}.mixed{background:#fff6e0;border-color:#d99a00}
.note{color:#59636e;font-size:13px}
table{border-collapse:collapse;margin:8px 0 14px;font-size:13.5px;font-variant-numeric:tabular-nums}
caption{caption-side:top;text-align:left;font-size:13px;color:#59636e;padding-bottom:4px}
th,td{padding:4px 10px;border-bottom:1px solid #e3e6ea;text-align:right;white-space:nowrap}
th{background:#f0f2f5;font-weight:600}td.l,th.l{text-align:left}
tr:hover td{background:#f7f9fb}
table.sortable th{cursor:pointer;user-select:none}table.sortable th:after{content:" \\2195";color:#9aa3ad}
figure{margin:10px 0 18px}figure img{max-width:100%;height:auto;border:1px solid #e3e6ea}
figcaption{font-size:13px;color:#59636e}
.code{position:relative;display:inline-block;margin:4px 12px 10px 0;vertical-align:top;max-width:100%}
.code pre{background:#1d232b;color:#e8eaed;padding:10px 64px 10px 12px;border-radius:6px;margin:0;font-size:12.5px;white-space:pre-wrap;word-break:break-all}
.code .t{font-size:13px;font-weight:600;margin-bottom:2px}
.code button{position:absolute;top:22px;right:6px;font-size:12px;padding:2px 8px;border:0;border-radius:4px;cursor:pointer}
details{margin:2px 0;border-left:3px solid #e3e6ea;padding-left:10px}details[open]{border-color:#3b6fb6}
details summary{cursor:pointer;font-size:13.5px}details table{margin-top:4px}
"""

# Copy buttons and sortable tables; no library (the page must open offline and stay small).
_JS = """
function copyText(btn){var t=btn.parentNode.querySelector('pre').innerText;
 function done(){btn.textContent='copied';setTimeout(function(){btn.textContent='copy'},1200)}
 if(navigator.clipboard&&window.isSecureContext){navigator.clipboard.writeText(t).then(done,function(){fallback(t);done()})}
 else{fallback(t);done()}}
function fallback(t){var a=document.createElement('textarea');a.value=t;document.body.appendChild(a);a.select();
 try{document.execCommand('copy')}catch(e){}document.body.removeChild(a)}
function sortTable(th){var table=th.closest('table'),body=table.tBodies[0],i=Array.prototype.indexOf.call(th.parentNode.children,th);
 var asc=th.dataset.dir!=='asc';Array.prototype.forEach.call(th.parentNode.children,function(h){delete h.dataset.dir});th.dataset.dir=asc?'asc':'desc';
 var rows=Array.prototype.slice.call(body.rows);rows.sort(function(a,b){var x=a.cells[i].dataset.v||a.cells[i].innerText,y=b.cells[i].dataset.v||b.cells[i].innerText;
 var nx=parseFloat(x),ny=parseFloat(y);var c=(!isNaN(nx)&&!isNaN(ny))?nx-ny:x.localeCompare(y);return asc?c:-c});
 rows.forEach(function(r){body.appendChild(r)})}
function openTarget(){var d=document.getElementById(decodeURIComponent(location.hash.slice(1)));
 if(d&&d.tagName==='DETAILS'){d.open=true;d.scrollIntoView()}}
window.addEventListener('hashchange',openTarget);window.addEventListener('load',openTarget);
"""


def render_html(title: str, blocks: list[Block]) -> str:
    """One self-contained HTML page: figures as data URIs, style and script inline."""
    body = "\n".join(_html_block(b) for b in blocks)
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width,initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_CSS}</style></head>\n<body><main>\n<h1>{_e(title)}</h1>\n{body}\n"
        f"</main><script>{_JS}</script></body></html>\n"
    )


def render_markdown(title: str, blocks: list[Block], figure_dir: str) -> str:
    """The same content as Markdown; figures referenced as ``figure_dir/<name>`` (written by the caller)."""
    out = [f"# {title}", ""]
    for b in blocks:
        out += _md_block(b, figure_dir) + [""]
    return "\n".join(out)


def write_figures(blocks: list[Block], folder: Path) -> None:
    """Each figure's PNG into ``folder`` (for report.md)."""
    folder.mkdir(parents=True, exist_ok=True)
    for b in blocks:
        if isinstance(b, Figure):
            write_bytes(folder / b.name, b.png)


def _e(text: str) -> str:
    return html.escape(str(text), quote=True)


def _html_block(b: Block) -> str:
    if isinstance(b, Heading):
        anchor = re.sub(r"[^a-z0-9]+", "-", b.text.lower()).strip("-")
        return f'<h{b.level} id="{anchor}">{_e(b.text)}</h{b.level}>'
    if isinstance(b, Paragraph):
        return f'<p class="{_e(b.css)}">{_e(b.text)}</p>' if b.css else f"<p>{_e(b.text)}</p>"
    if isinstance(b, Table):
        return _html_table(b)
    if isinstance(b, Figure):
        data = base64.b64encode(b.png).decode("ascii")
        return (
            f'<figure><img src="data:image/png;base64,{data}" alt="{_e(b.caption)}">'
            f"<figcaption>{_e(b.caption)}</figcaption></figure>"
        )
    if isinstance(b, Code):
        title = f'<div class="t">{_e(b.title)}</div>' if b.title else ""
        return f'<div class="code">{title}<pre>{_e(b.text)}</pre><button type="button" onclick="copyText(this)">copy</button></div>'
    if isinstance(b, Details):
        anchor = f' id="{_e(b.anchor)}"' if b.anchor else ""
        inner = "".join(_html_block(x) for x in b.blocks)
        return f"<details{anchor}><summary>{_e(b.summary)}</summary>{inner}</details>"
    raise TypeError(f"not a report block: {b!r}")


def _html_table(t: Table) -> str:
    numeric = t.numeric or tuple(i > 0 for i in range(len(t.header)))
    cls = lambda i: "" if numeric[i] else ' class="l"'  # noqa: E731
    click = ' onclick="sortTable(this)"' if t.sortable else ""
    head = "".join(f"<th{cls(i)}{click}>{_e(h)}</th>" for i, h in enumerate(t.header))
    rows = []
    for r, row in enumerate(t.rows):
        cells = []
        for c, cell in enumerate(row):
            text = _e(cell)
            if (r, c) in t.links:
                text = f'<a href="{_e(t.links[(r, c)])}">{text}</a>'
            cells.append(f"<td{cls(c)}>{text}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    caption = f"<caption>{_e(t.caption)}</caption>" if t.caption else ""
    sortable = ' class="sortable"' if t.sortable else ""
    sortable += f' id="{_e(t.anchor)}"' if t.anchor else ""
    return f"<table{sortable}>{caption}<thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


def _md_block(b: Block, figure_dir: str) -> list[str]:
    if isinstance(b, Heading):
        return ["#" * b.level + " " + b.text]
    if isinstance(b, Paragraph):
        return [f"**{b.text}**" if "verdict" in b.css else b.text]
    if isinstance(b, Table):
        cell = lambda s: str(s).replace("|", "\\|")  # noqa: E731
        lines = [f"*{b.caption}*", ""] if b.caption else []
        lines.append("| " + " | ".join(cell(h) for h in b.header) + " |")
        lines.append("| " + " | ".join("---" for _ in b.header) + " |")
        for r, row in enumerate(b.rows):
            cells = [f"[{cell(v)}]({b.links[(r, c)]})" if (r, c) in b.links else cell(v) for c, v in enumerate(row)]
            lines.append("| " + " | ".join(cells) + " |")
        return lines
    if isinstance(b, Figure):
        return [f"![{b.caption}]({figure_dir}/{b.name})", "", f"*{b.caption}*"]
    if isinstance(b, Code):
        return ([f"{b.title}:", ""] if b.title else []) + ["```", b.text, "```"]
    if isinstance(b, Details):  # a heading with an anchor the tables' links point to; Markdown cannot fold
        anchor = f'<a id="{b.anchor}"></a>' if b.anchor else ""
        lines = [f"#### {anchor}{b.summary}", ""]
        for x in b.blocks:
            lines += _md_block(x, figure_dir) + [""]
        return lines[:-1]
    raise TypeError(f"not a report block: {b!r}")
