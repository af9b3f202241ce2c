"""One self-contained HTML page from the results of ``dgse bench``.

:func:`write_report` reads the manifest ``suite.json`` of every suite under a
results directory (:func:`dgse.bench.core.load_manifests`) and writes one HTML
file (``DIR/report.html`` by default) that needs nothing else:

* every figure is embedded as a base64 ``data:`` URI, there are no external
  style sheets, fonts or scripts, and the page makes no network request;
* tables are rendered from the rows stored in the manifest (numbers to four
  significant digits), with their captions;
* each suite shows its title, description, the exact command, wall time,
  versions and hardware, notes, and its sections (text, figures, tables);
* ``DIR/summary.md`` is rendered at the top of the page: it is written first, from the
  suites' result files (:func:`dgse.bench.summary.write_summary`), so it is never typed by hand.

Text (descriptions, section text, notes, captions and ``summary.md``) is
read as a small subset of Markdown (:func:`markdown_to_html`): paragraphs,
``-`` and ``1.`` lists, ``#`` headings, fenced code blocks, pipe tables,
inline code in backticks and ``**bold**``; everything else is shown as
written, HTML-escaped.

A short inline script marks, once the page has loaded, every ``<img>`` with
``data-rendered="1"`` (decoded and drawn) or ``"0"``, and the body with
``data-images-checked="1"``, so a headless browser can check the page.
"""

from __future__ import annotations

import base64
import csv
import datetime as _dt
import html
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dgse.bench.core import MANIFEST, load_manifests
from dgse.errors import InputDataError
from dgse.files import write_text

__all__ = ["format_value", "markdown_to_html", "write_report"]

#: The file the report is written to inside the results directory by default.
REPORT_NAME = "report.html"
#: Markdown rendered at the top of the page (written by :func:`dgse.bench.summary.write_summary`).
SUMMARY_NAME = "summary.md"

_MIME = {
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".gif": "image/gif",
    ".svg": "image/svg+xml",
    ".webp": "image/webp",
}


def _esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


# -- numbers -----------------------------------------------------------------------------
def format_value(value: Any, digits: int = 4) -> str:
    """``value`` as HTML for a table cell: floats to ``digits`` significant digits.

    None (a missing or non-finite value in the manifest) is an en dash; very
    large or small floats use ``m × 10<sup>e</sup>``; booleans are yes/no;
    lists and mappings are compact JSON.  Strings are escaped.
    """
    if value is None:
        return "\u2013"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return _esc(value)
        if value == 0:
            return "0"
        a = abs(value)
        if 1e-3 <= a < 1e4:
            return f"{value:.{digits}g}"
        if 1e4 <= a < 1e9:
            return f"{value:,.0f}"
        mantissa, exp = f"{value:.{digits - 1}e}".split("e")
        mantissa = mantissa.rstrip("0").rstrip(".") if "." in mantissa else mantissa
        return f"{mantissa}\u202f\u00d7\u202f10<sup>{int(exp)}</sup>"
    if isinstance(value, (list, tuple, Mapping)):
        return _esc(json.dumps(value, separators=(", ", ": ")))
    return _esc(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _fmt_duration(seconds: Any) -> str:
    if not _is_number(seconds) or not math.isfinite(seconds):
        return "\u2013"
    s = float(seconds)
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        m, r = divmod(round(s), 60)
        return f"{m} min {r:02d} s"
    h, r = divmod(round(s), 3600)
    return f"{h} h {r // 60:02d} min"


def _fmt_time(stamp: Any) -> str:
    if not isinstance(stamp, str) or not stamp:
        return "\u2013"
    try:
        t = _dt.datetime.fromisoformat(stamp)
    except ValueError:
        return stamp
    if t.tzinfo is not None:
        t = t.astimezone(_dt.UTC)
        return t.strftime("%Y-%m-%d %H:%M UTC")
    return t.strftime("%Y-%m-%d %H:%M")


# -- a tiny Markdown ---------------------------------------------------------------------
_INLINE_CODE = re.compile(r"`([^`\n]+)`")
_BOLD = re.compile(r"\*\*(?=\S)(.+?)(?<=\S)\*\*")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)(?:\s+#+)?\s*$")
_BULLET = re.compile(r"^\s{0,3}[-*+]\s+(.*)$")
_NUMBERED = re.compile(r"^\s{0,3}\d{1,9}[.)]\s+(.*)$")
_TABLE_SEP = re.compile(r"^\s*\|?\s*:?-{2,}:?\s*(\|\s*:?-{2,}:?\s*)*\|?\s*$")
_FENCE = re.compile(r"^\s{0,3}(```|~~~)")


def _inline(text: str) -> str:
    """Escape ``text`` and render inline code (backticks) and ``**bold**`` in it."""
    codes: list[str] = []

    def stash(m: re.Match[str]) -> str:
        codes.append(f"<code>{_esc(m.group(1))}</code>")
        return f"\x00{len(codes) - 1}\x00"

    out = _BOLD.sub(r"<strong>\1</strong>", _esc(_INLINE_CODE.sub(stash, text.replace("\x00", ""))))
    return re.sub("\x00(\\d+)\x00", lambda m: codes[int(m.group(1))], out)


def _split_row(line: str) -> list[str]:
    s = line.strip()
    if s.startswith("|"):
        s = s[1:]
    if s.endswith("|"):
        s = s[:-1]
    return [c.strip() for c in s.split("|")]


def _md_table(lines: list[str]) -> str:
    head = _split_row(lines[0])
    aligns = []
    for c in _split_row(lines[1]):
        if c.startswith(":") and c.endswith(":"):
            aligns.append("center")
        elif c.endswith(":"):
            aligns.append("right")
        else:
            aligns.append("")

    def cell(tag: str, text: str, k: int) -> str:
        a = aligns[k] if k < len(aligns) else ""
        style = f' style="text-align:{a}"' if a else ""
        return f"<{tag}{style}>{_inline(text)}</{tag}>"

    parts = ['<div class="scroll"><table class="data">', "<thead><tr>"]
    parts += [cell("th", c, k) for k, c in enumerate(head)]
    parts.append("</tr></thead><tbody>")
    for line in lines[2:]:
        cells = _split_row(line)
        cells += [""] * (len(head) - len(cells))
        parts.append("<tr>" + "".join(cell("td", c, k) for k, c in enumerate(cells)) + "</tr>")
    parts.append("</tbody></table></div>")
    return "".join(parts)


def markdown_to_html(text: str, heading_level: int | None = None) -> str:
    """HTML of ``text`` read as a small subset of Markdown (see the module doc).

    Args:
        text: the Markdown source; anything not understood is shown as text.
        heading_level: the HTML level of a ``#`` heading (``##`` is one deeper,
            at most ``h6``); None shows ``#`` lines as text.
    """
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    blocks: list[str] = []
    para: list[str] = []
    items: list[str] = []
    list_tag = ""

    def flush() -> None:
        nonlocal list_tag
        if para:
            blocks.append("<p>" + "\n".join(_inline(p) for p in para) + "</p>")
            para.clear()
        if items:
            blocks.append(
                f"<{list_tag}>" + "".join(f"<li>{_inline(it)}</li>" for it in items) + f"</{list_tag}>"
            )
            items.clear()
            list_tag = ""

    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if not stripped:
            flush()
            i += 1
            continue
        fence = _FENCE.match(line)
        if fence:
            flush()
            body = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith(fence.group(1)):
                body.append(lines[i])
                i += 1
            blocks.append("<pre><code>" + _esc("\n".join(body)) + "</code></pre>")
            i += 1
            continue
        heading = _HEADING.match(stripped) if heading_level is not None else None
        if heading:
            flush()
            level = min(6, heading_level + len(heading.group(1)) - 1)
            blocks.append(f"<h{level}>{_inline(heading.group(2))}</h{level}>")
            i += 1
            continue
        if stripped.startswith("|") and i + 1 < len(lines) and _TABLE_SEP.match(lines[i + 1]):
            flush()
            rows = [line, lines[i + 1]]
            i += 2
            while i < len(lines) and lines[i].strip().startswith("|"):
                rows.append(lines[i])
                i += 1
            blocks.append(_md_table(rows))
            continue
        bullet = _BULLET.match(line)
        numbered = _NUMBERED.match(line) if not bullet else None
        if bullet or numbered:
            tag = "ul" if bullet else "ol"
            if para or (items and list_tag != tag):
                flush()
            list_tag = tag
            items.append((bullet or numbered).group(1).strip())
        elif items:
            # a continuation line of the last list item (a blank line ends the list)
            items[-1] += " " + stripped
        else:
            para.append(stripped)
        i += 1
    flush()
    return "\n".join(blocks)


# -- pieces of the page ------------------------------------------------------------------
def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "x"


def _image_uri(path: Path) -> str:
    mime = _MIME.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _read_csv(path: Path) -> tuple[list[str], list[list[Any]]]:
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return [], []

    def parse(v: str) -> Any:
        if v == "":
            return None
        for kind in (int, float):
            try:
                return kind(v)
            except ValueError:
                pass
        return v

    return rows[0], [[parse(v) for v in r] for r in rows[1:]]


class _Counter:
    def __init__(self) -> None:
        self.figures = 0
        self.tables = 0


def _figure_html(fig: Mapping[str, Any], suite_dir: Path, count: _Counter) -> str:
    name = str(fig.get("file", ""))
    caption = str(fig.get("caption", ""))
    path = suite_dir / name
    if not name or not path.is_file():
        return (
            '<div class="missing">Figure file missing: '
            f"<code>{_esc(suite_dir.name + '/' + name)}</code>"
            + (f" ({_inline(caption)})" if caption else "")
            + "</div>"
        )
    count.figures += 1
    return (
        '<figure class="fig">'
        f'<img src="{_image_uri(path)}" alt="{_esc(caption or name)}">'
        f'<figcaption><span class="label">Figure {count.figures}.</span> {_inline(caption)}'
        f' <span class="file">{_esc(suite_dir.name + "/" + name)}</span></figcaption>'
        "</figure>"
    )


def _table_html(table: Mapping[str, Any], suite_dir: Path, count: _Counter) -> str:
    name = str(table.get("file", ""))
    caption = str(table.get("caption", ""))
    columns = list(table.get("columns") or [])
    rows = table.get("rows")
    if rows is None:
        path = suite_dir / name
        if name and path.is_file():
            columns, rows = _read_csv(path)
        else:
            return (
                '<div class="missing">Table missing: '
                f"<code>{_esc(suite_dir.name + '/' + name)}</code>"
                + (f" ({_inline(caption)})" if caption else "")
                + "</div>"
            )
    rows = [list(r) if isinstance(r, (list, tuple)) else [r] for r in rows]
    width = max([len(columns), *(len(r) for r in rows)]) if (columns or rows) else 0
    columns = [*columns, *([""] * (width - len(columns)))]
    numeric = [
        any(_is_number(r[k]) for r in rows if k < len(r))
        and all(r[k] is None or _is_number(r[k]) for r in rows if k < len(r))
        for k in range(width)
    ]
    count.tables += 1
    parts = [
        '<figure class="tab">',
        f'<figcaption><span class="label">Table {count.tables}.</span> {_inline(caption)}'
        + (f' <span class="file">{_esc(suite_dir.name + "/" + name)}</span>' if name else "")
        + "</figcaption>",
        '<div class="scroll"><table class="data"><thead><tr>',
    ]
    cls = [' class="num"' if numeric[k] else "" for k in range(width)]
    parts += [f"<th{cls[k]}>{_esc(c)}</th>" for k, c in enumerate(columns)]
    parts.append("</tr></thead><tbody>")
    for r in rows:
        cells = [*r, *([""] * (width - len(r)))]
        parts.append(
            "<tr>" + "".join(f"<td{cls[k]}>{format_value(v)}</td>" for k, v in enumerate(cells)) + "</tr>"
        )
    if not rows:
        parts.append(f'<tr><td colspan="{max(width, 1)}" class="empty">no rows</td></tr>')
    parts.append("</tbody></table></div></figure>")
    return "".join(parts)


def _versions_text(versions: Any) -> str:
    if not isinstance(versions, Mapping):
        return ""
    return ", ".join(f"{_esc(k)}&nbsp;{_esc(v)}" for k, v in versions.items() if v)


def _data_text(data: Any) -> str:
    if not isinstance(data, Mapping):
        return _esc(data) if data else ""
    parts = []
    if data.get("store"):
        parts.append(f"<code>{_esc(data['store'])}</code>")
        if data.get("split"):
            parts.append(f"{_esc(data['split'])} split")
        layouts = data.get("layouts")
        if isinstance(layouts, list):
            parts.append(f"{len(layouts)} layout{'s' * (len(layouts) != 1)}")
    elif data.get("generated"):
        parts.append(_inline(str(data["generated"])))
    for k, v in data.items():
        if k not in ("store", "split", "layouts", "generated") and v is not None:
            parts.append(f"{_esc(k)}: {format_value(v)}")
    return "; ".join(parts)


def _cost(m: Mapping[str, Any]) -> Any:
    """A suite's time: its wall time, or its compute time over resumed runs when that is larger."""
    w, c = m.get("wall_seconds"), m.get("compute_seconds")
    if _is_number(w) and _is_number(c):
        return max(float(w), float(c))
    return w


def _meta_html(m: Mapping[str, Any]) -> str:
    env = m.get("environment") if isinstance(m.get("environment"), Mapping) else {}
    rows: list[tuple[str, str]] = []
    if m.get("command"):
        rows.append(("Command", f'<pre class="cmd"><code>{_esc(m["command"])}</code></pre>'))
    run = [f"wall time <strong>{_fmt_duration(m.get('wall_seconds'))}</strong>"]
    if _is_number(m.get("compute_seconds")) and _is_number(m.get("wall_seconds")):
        if float(m["compute_seconds"]) > float(m["wall_seconds"]):
            run.append(f"compute time over all resumed runs {_fmt_duration(m['compute_seconds'])}")
    run.append("quick run" if m.get("quick") else "full run")
    if m.get("seed") is not None:
        run.append(f"seed {_esc(m['seed'])}")
    if m.get("started") or m.get("finished"):
        run.append(f"{_fmt_time(m.get('started'))} \u2192 {_fmt_time(m.get('finished'))}")
    rows.append(("Run", " \u00b7 ".join(run)))
    data = _data_text(m.get("data"))
    if data:
        rows.append(("Scenarios", data))
    software = []
    if env.get("python"):
        software.append(f"Python&nbsp;{_esc(env['python'])}")
    versions = _versions_text(env.get("versions"))
    if versions:
        software.append(versions)
    if software:
        rows.append(("Software", ", ".join(software)))
    hardware = []
    if env.get("cpu"):
        cores = f" ({_esc(env['cpu_count'])} cores)" if env.get("cpu_count") else ""
        hardware.append(f"{_esc(env['cpu'])}{cores}")
    hardware.append(f"GPU: {_esc(env['gpu'])}" if env.get("gpu") else "no GPU")
    if env.get("torch_threads"):
        hardware.append(f"{_esc(env['torch_threads'])} torch threads")
    if env.get("platform"):
        hardware.append(_esc(env["platform"]))
    rows.append(("Hardware", " \u00b7 ".join(hardware)))
    return '<dl class="meta">' + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>"


def _suite_html(m: Mapping[str, Any], number: int, anchor: str, count: _Counter) -> str:
    suite_dir = Path(m["_dir"])
    title = str(m.get("title") or m.get("suite") or suite_dir.name)
    badge = '<span class="badge quick">quick</span>' if m.get("quick") else ""
    parts = [
        f'<section class="suite" id="{anchor}">',
        f'<h2><span class="idx">{number}</span> {_inline(title)} '
        f'<span class="suite-name">{_esc(m.get("suite") or suite_dir.name)}</span>{badge}</h2>',
    ]
    if m.get("description"):
        parts.append(f'<div class="description">{markdown_to_html(str(m["description"]))}</div>')
    parts.append(_meta_html(m))
    notes = [n for n in (m.get("notes") or []) if str(n).strip()]
    if notes:
        parts.append(
            '<div class="notes"><strong>Notes</strong><ul>'
            + "".join(f"<li>{_inline(str(n))}</li>" for n in notes)
            + "</ul></div>"
        )
    sections = m.get("sections") or []
    if not sections:
        parts.append('<p class="empty">This suite wrote no sections.</p>')
    for k, sec in enumerate(sections, 1):
        parts.append(f'<section class="part" id="{anchor}-{k}">')
        parts.append(f'<h3><span class="idx">{number}.{k}</span> {_inline(str(sec.get("title", "")))}</h3>')
        if sec.get("text"):
            parts.append(f'<div class="text">{markdown_to_html(str(sec["text"]), heading_level=4)}</div>')
        parts += [_figure_html(f, suite_dir, count) for f in sec.get("figures") or []]
        parts += [_table_html(t, suite_dir, count) for t in sec.get("tables") or []]
        parts.append("</section>")
    parts.append("</section>")
    return "\n".join(parts)


def _toc_html(manifests: Sequence[Mapping[str, Any]], anchors: Sequence[str]) -> str:
    parts = ['<nav class="toc"><h2>Contents</h2><ol>']
    for n, (m, anchor) in enumerate(zip(manifests, anchors, strict=True), 1):
        title = str(m.get("title") or m.get("suite") or "")
        quick = " \u00b7 quick" if m.get("quick") else ""
        parts.append(
            f'<li><span class="goto" data-goto="{anchor}" tabindex="0" role="button">'
            f'<span class="idx">{n}</span> {_inline(title)}</span>'
            f'<span class="toc-meta">{_fmt_duration(_cost(m))}{quick}</span>'
        )
        sections = m.get("sections") or []
        if sections:
            parts.append("<ol>")
            for k, sec in enumerate(sections, 1):
                parts.append(
                    f'<li><span class="goto" data-goto="{anchor}-{k}" tabindex="0" role="button">'
                    f'<span class="idx">{n}.{k}</span> {_inline(str(sec.get("title", "")))}</span></li>'
                )
            parts.append("</ol>")
        parts.append("</li>")
    parts.append("</ol></nav>")
    return "".join(parts)


def _order(manifests: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The manifests in the order ``dgse bench all`` runs the suites, unknown suites last."""
    try:
        from dgse.bench import SUITES

        known = list(SUITES)
    except ImportError:  # pragma: no cover - the registry is part of the package
        known = []
    rank = {name: i for i, name in enumerate(known)}
    return sorted(manifests, key=lambda m: (rank.get(str(m.get("suite")), len(rank)), str(m.get("suite"))))


_CSS = """
:root {
  --fg: #1d2433; --muted: #5f6b7a; --accent: #2557d6; --border: #e2e6ec;
  --bg: #f5f7fa; --card: #ffffff; --code-bg: #eef1f5; --head-bg: #f0f3f8;
}
* { box-sizing: border-box; }
html { -webkit-text-size-adjust: 100%; }
body {
  margin: 0; background: var(--bg); color: var(--fg);
  font: 16px/1.6 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
}
main { max-width: 1100px; margin: 0 auto; padding: 2.5rem 1.25rem 4rem; }
h1, h2, h3, h4 { line-height: 1.25; margin: 1.6em 0 .6em; }
h1 { font-size: 2rem; margin-top: 0; letter-spacing: -.01em; }
h2 { font-size: 1.45rem; }
h3 { font-size: 1.15rem; }
h4 { font-size: 1rem; }
p { margin: .6em 0; }
code {
  font: .88em/1.4 ui-monospace, SFMono-Regular, Menlo, Consolas, "DejaVu Sans Mono", monospace;
  background: var(--code-bg); padding: .1em .35em; border-radius: 4px;
}
pre { background: var(--code-bg); padding: .75rem 1rem; border-radius: 6px; overflow-x: auto; }
pre code { background: none; padding: 0; }
header.page { border-bottom: 3px solid var(--accent); padding-bottom: 1rem; margin-bottom: 1.5rem; }
header.page .sub { color: var(--muted); margin: 0; }
.card, section.suite, nav.toc, section.summary {
  background: var(--card); border: 1px solid var(--border); border-radius: 10px;
  padding: 1.4rem 1.75rem; margin: 1.75rem 0; box-shadow: 0 1px 3px rgba(16, 24, 40, .05);
}
section.summary > :first-child, nav.toc > h2 { margin-top: 0; }
nav.toc ol { list-style: none; padding-left: 0; margin: .3rem 0; }
nav.toc ol ol { padding-left: 1.9rem; font-size: .93rem; }
nav.toc li { margin: .15rem 0; }
nav.toc .goto { cursor: pointer; }
nav.toc .goto:hover, nav.toc .goto:focus { color: var(--accent); text-decoration: underline; outline: none; }
nav.toc .toc-meta { color: var(--muted); font-size: .85rem; margin-left: .6rem; }
.idx { color: var(--accent); font-variant-numeric: tabular-nums; margin-right: .35rem; }
section.suite h2 { margin-top: 0; padding-bottom: .45rem; border-bottom: 1px solid var(--border); }
.suite-name {
  font: 500 .8rem ui-monospace, SFMono-Regular, Menlo, Consolas, "DejaVu Sans Mono", monospace;
  color: var(--muted); margin-left: .5rem; vertical-align: middle;
}
.badge {
  display: inline-block; font-size: .72rem; font-weight: 600; text-transform: uppercase;
  letter-spacing: .04em; padding: .12rem .5rem; border-radius: 999px; margin-left: .5rem;
  vertical-align: middle;
}
.badge.quick { background: #fff4d6; color: #8a5a00; border: 1px solid #f3d58b; }
.description { color: #364152; }
dl.meta {
  display: grid; grid-template-columns: max-content minmax(0, 1fr); gap: .3rem 1.1rem;
  font-size: .88rem; background: #fafbfd; border: 1px solid var(--border); border-radius: 8px;
  padding: .8rem 1rem; margin: 1rem 0;
}
dl.meta dt { color: var(--muted); font-weight: 600; }
dl.meta dd { margin: 0; overflow-wrap: anywhere; }
pre.cmd { margin: 0; padding: .45rem .7rem; background: #1e2433; color: #e6e9ef; }
pre.cmd code { color: inherit; white-space: pre-wrap; word-break: break-all; }
.notes {
  background: #fff9eb; border-left: 4px solid #f0b429; border-radius: 6px;
  padding: .6rem 1rem; margin: 1rem 0; font-size: .93rem;
}
.notes ul { margin: .3rem 0 0; padding-left: 1.3rem; }
section.part { margin-top: 2rem; }
figure { margin: 1.5rem 0; }
figure.fig img {
  display: block; max-width: 100%; height: auto; margin: 0 auto;
  border: 1px solid var(--border); border-radius: 6px; background: #fff;
}
figcaption { font-size: .9rem; color: #364152; margin-top: .5rem; }
figure.fig figcaption { text-align: center; max-width: 52rem; margin-left: auto; margin-right: auto; }
figure.tab figcaption { margin: 0 0 .5rem; }
figcaption .label { font-weight: 700; color: var(--fg); }
figcaption .file {
  color: var(--muted); font-family: ui-monospace, Menlo, Consolas, monospace; font-size: .78rem;
}
.scroll { overflow-x: auto; border: 1px solid var(--border); border-radius: 8px; }
table.data { border-collapse: collapse; width: 100%; font-size: .88rem; font-variant-numeric: tabular-nums; }
table.data th, table.data td {
  padding: .4rem .75rem; border-bottom: 1px solid var(--border); text-align: left;
}
table.data th { background: var(--head-bg); font-weight: 600; white-space: nowrap; }
table.data tbody tr:nth-child(even) { background: #fafbfd; }
table.data tbody tr:hover { background: #eef3ff; }
table.data tbody tr:last-child td { border-bottom: none; }
table.data .num { text-align: right; white-space: nowrap; }
.missing {
  color: #9b1c1c; background: #fdecec; border-radius: 6px; padding: .5rem .8rem; margin: 1rem 0;
}
.empty { color: var(--muted); font-style: italic; }
footer { color: var(--muted); font-size: .85rem; text-align: center; margin-top: 3rem; }
@media (max-width: 640px) {
  main { padding: 1.25rem .75rem 3rem; }
  .card, section.suite, nav.toc, section.summary { padding: 1rem; }
  dl.meta { grid-template-columns: 1fr; }
}
@media print {
  body { background: #fff; }
  section.suite, nav.toc, section.summary { box-shadow: none; border: none; padding: 0; }
  figure { break-inside: avoid; }
}
"""

_SCRIPT = """
window.addEventListener("load", function () {
  var imgs = document.getElementsByTagName("img");
  for (var i = 0; i < imgs.length; i++) {
    var img = imgs[i];
    img.setAttribute("data-rendered", img.complete && img.naturalWidth > 0 ? "1" : "0");
  }
  document.body.dataset.imagesChecked = "1";
});
function dgseGoto(e) {
  var t = e.target.closest ? e.target.closest("[data-goto]") : null;
  if (!t || (e.type === "keydown" && e.key !== "Enter" && e.key !== " ")) return;
  var el = document.getElementById(t.getAttribute("data-goto"));
  if (el) { e.preventDefault(); el.scrollIntoView({behavior: "smooth", block: "start"}); }
}
document.addEventListener("click", dgseGoto);
document.addEventListener("keydown", dgseGoto);
"""


def _load(directory: Path) -> list[dict[str, Any]]:
    if not directory.exists():
        raise InputDataError(f"{directory}: no such results directory")
    if not directory.is_dir():
        raise InputDataError(f"{directory}: not a directory (give the output directory of dgse bench)")
    try:
        manifests = load_manifests(directory)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputDataError(f"{directory}: a suite manifest {MANIFEST} cannot be read: {e}") from e
    if not manifests:
        raise InputDataError(
            f"{directory}: no suite results (no */{MANIFEST}); run `dgse bench SUITE --out {directory}` first"
        )
    return _order(manifests)


def write_report(
    directory: str | os.PathLike[str],
    output: str | os.PathLike[str] | None = None,
    *,
    summary: bool = True,
) -> Path:
    """Write ``DIR/summary.md`` and the HTML page of every suite's results under ``directory``;
    return the page's path.

    Args:
        directory: the output directory of ``dgse bench`` (``DIR/<suite>/suite.json``).
        output: the HTML file (default ``DIR/report.html``).
        summary: write ``DIR/summary.md`` from the suites' result files first
            (:func:`dgse.bench.summary.write_summary`); False renders the one that is there.

    Raises:
        InputDataError: ``directory`` does not exist or holds no suite results.
    """
    root = Path(directory)
    manifests = _load(root)
    out = Path(output) if output is not None else root / REPORT_NAME
    if summary:
        from dgse.bench.summary import write_summary

        write_summary(root, root / SUMMARY_NAME)

    count = _Counter()
    anchors = []
    for m in manifests:
        base = f"suite-{_slug(str(m.get('suite') or Path(m['_dir']).name))}"
        anchor, k = base, 2
        while anchor in anchors:
            anchor, k = f"{base}-{k}", k + 1
        anchors.append(anchor)

    done = {Path(m["_dir"]).name for m in manifests}
    unfinished = sorted(
        p.name
        for p in root.iterdir()
        if p.is_dir() and not p.name.startswith(("_", ".")) and p.name not in done
    )
    total = sum(float(_cost(m)) for m in manifests if _is_number(_cost(m)))
    quick = any(m.get("quick") for m in manifests)
    generated = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")

    body = ["<main>", '<header class="page">', "<h1>DGSE benchmark report</h1>"]
    sub = [
        f"{len(manifests)} suite{'s' * (len(manifests) != 1)}",
        f"total wall time {_fmt_duration(total)}",
        f"generated {generated}",
    ]
    if quick:
        sub.append("includes quick (CI-sized) runs")
    body.append('<p class="sub">' + " \u00b7 ".join(sub) + "</p></header>")
    summary_file = root / SUMMARY_NAME
    if summary_file.is_file():
        html_text = markdown_to_html(summary_file.read_text(errors="replace"), 2)
        body.append(f'<section class="summary">{html_text}</section>')
    body.append(_toc_html(manifests, anchors))
    if unfinished:
        body.append(
            '<div class="notes"><strong>Suites without results</strong> (interrupted or still running): '
            + ", ".join(f"<code>{_esc(n)}</code>" for n in unfinished)
            + "</div>"
        )
    for n, (m, anchor) in enumerate(zip(manifests, anchors, strict=True), 1):
        body.append(_suite_html(m, n, anchor, count))
    body.append(
        f"<footer>{count.figures} figure{'s' * (count.figures != 1)}, "
        f"{count.tables} table{'s' * (count.tables != 1)} \u00b7 written by <code>dgse report</code></footer>"
    )
    body.append("</main>")

    page = "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            "<title>DGSE benchmark report</title>",
            f"<style>{_CSS}</style>",
            "</head>",
            "<body>",
            *body,
            f"<script>{_SCRIPT}</script>",
            "</body>",
            "</html>",
            "",
        ]
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out, page)
    return out
