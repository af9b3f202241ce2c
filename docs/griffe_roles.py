"""A griffe extension for the API reference: two docstring conventions of DGSE made Markdown.

DGSE's docstrings name other objects the way Sphinx does (``:func:`name```,
``:class:`~dgse.belief.Belief```, ``:mod:`dgse.physics.rans```).  Markdown has no such
roles, so this turns each one into an optional cross-reference of mkdocs-autorefs: a link
where the target is documented on the site, plain code where it is not (a name relative to
its module, or an object the reference leaves out).  A leading ``~`` shows the last part of
the name only, as in Sphinx.

Several parameters that share one description are documented on one line
(``K, T: Monte Carlo samples``).  Griffe's Google-style parser takes one name per
entry, so such an entry is written out once per name, each with the whole description:
the rendered table lists every parameter, and a name that is not in the signature still
gets griffe's warning.  Nothing else of a docstring is changed.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

SECTION = re.compile(r"^(\s*)(Args|Arguments|Parameters|Params|Attributes|Other Parameters):\s*$")
NAMES = re.compile(r"^(\s+)([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)+)\s*(\(.*?\))?:(\s.*|)$")
ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|data|attr|exc|obj|const|type):`(~?)([^`<>]+?)`")


def _replace(match: re.Match[str]) -> str:
    short, target = match.group(1), match.group(2).strip()
    shown = target.rsplit(".", 1)[-1] if short else target
    return f'<autoref identifier="{html.escape(target)}" optional><code>{html.escape(shown)}</code></autoref>'


def roles_to_links(text: str) -> str:
    """``text`` with every Sphinx role replaced by an optional autorefs link."""
    return ROLE.sub(_replace, text)


def split_shared_names(text: str) -> str:
    """``text`` with every ``a, b: description`` entry of a parameter section written as one
    entry per name."""
    lines = text.splitlines()
    out: list[str] = []
    i, section = 0, None  # section: the indentation of the current section's header
    while i < len(lines):
        line = lines[i]
        head = SECTION.match(line)
        if head:
            section = len(head.group(1))
            out.append(line)
            i += 1
            continue
        indent = len(line) - len(line.lstrip())
        if section is not None and line.strip() and indent <= section:
            section = None
        m = NAMES.match(line) if section is not None else None
        if not m:
            out.append(line)
            i += 1
            continue
        body = [m.group(4).strip()]
        i += 1
        while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > indent):
            body.append(lines[i])
            i += 1
        trailing = 0
        while body and not body[-1].strip():
            body.pop()
            trailing += 1
        kind = f" {m.group(3)}" if m.group(3) else ""
        for name in (n.strip() for n in m.group(2).split(",")):
            out.append(f"{m.group(1)}{name}{kind}: {body[0]}".rstrip())
            out.extend(body[1:])
        out.extend([""] * trailing)
    return "\n".join(out)


class DocstringConventions(griffe.Extension):
    """Rewrites every docstring griffe loads: shared parameter entries, then Sphinx roles."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None and ":" in obj.docstring.value:
            obj.docstring.value = roles_to_links(split_shared_names(obj.docstring.value))
