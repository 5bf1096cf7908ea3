"""MkDocs hooks: the pages generated from microsim's own declarations, and the docstrings'
Sphinx roles shown as code in the API reference.

A page holds a marker ``<!-- generated: NAME -->``, which :func:`on_page_markdown` replaces with
the Markdown of ``GENERATORS[NAME]``: the models from their registry (parameters and ranges as
``microsim models`` prints them), the table format from :mod:`microsim.core.table_layout`, the config
keys from the config schema. The docs can then not drift from the code.
"""

from __future__ import annotations

import re

MARKER = re.compile(r"<!-- generated: ([a-z_-]+) -->")
#: a Sphinx cross-reference role of a docstring (``:class:`~microsim.app.progress.Progress```) as
#: mkdocstrings renders it, role and all
SPHINX_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):<code>(~?)([^<]+)</code>")


def models_page() -> str:
    from microsim import models

    lines = []
    for name in models.available():
        cls = models.get(name)
        summary = (cls.__doc__ or "").strip().split("\n\n")[0]
        lines += [f"## `{name}`", "", " ".join(summary.split()), "", f"Reference: {cls.reference}", ""]
        if not cls.reciprocal:
            lines += [f"Not reciprocal: {cls.nonreciprocal_reason}", ""]
        lines += ["| parameter | accepted | default | meaning |", "|---|---|---|---|"]
        for p in cls.params:
            lines.append(f"| `{p.name}` | {_cell(p.describe())} | {_cell(p.default_text())} | {_cell(p.doc)} |")
        lines += ["", "As `microsim models` prints it:", "", "```text", *models.listing([name]), "```", ""]
    return "\n".join(lines)


def table_format_page() -> str:
    from microsim import tables
    from microsim.core import table_layout

    lines = [f"Format version: **{table_layout.FORMAT_VERSION}** (the `format_version` attribute).", "",
             "### Attributes", "", "| attribute | of | meaning | present |", "|---|---|---|---|"]
    lines += [f"| `{a.name}` | {'the file' if a.group == '/' else a.group} | {_cell(a.doc)} | {_cell(a.when)} |"
              for a in tables.ATTRIBUTES]
    lines += ["", "### Axes", "", "| axis | length |", "|---|---|"]
    lines += [f"| `{axis}` | {_cell(length)} |" for axis, length in table_layout.AXIS_LENGTHS.items()]
    lines += ["", "### Datasets", "", "| dataset | axes | unit | meaning | present | required |",
              "|---|---|---|---|---|---|"]
    for d in tables.DATASETS:
        axes = "(" + ", ".join(d.axes) + ")" if d.axes is not None else "free"
        when = d.when if d.since == "1.0" else f"{d.when}; format {d.since} on"
        lines.append(f"| `{d.name}` | {axes} | {d.unit or '-'} | {_cell(d.doc)} | {_cell(when)} | "
                     f"{'yes' if d.required else ''} |")
    return "\n".join(lines)


def config_keys_page() -> str:
    from microsim import config
    from microsim.app import sweep

    lines = ["| key | kinds that have it | accepted | default | meaning |", "|---|---|---|---|---|"]
    for key in config.keys() + sweep.keys():
        lines.append(f"| `{key.name}` | {_cell(key.kinds or 'all')} | {_cell(key.accepted)} | {_cell(key.default)} | "
                     f"{_cell(key.doc)} |")
    return "\n".join(lines)


GENERATORS = {"models": models_page, "table-format": table_format_page, "config-keys": config_keys_page}


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def on_page_markdown(markdown: str, page, config, files) -> str:
    return MARKER.sub(lambda match: GENERATORS[match[1]](), markdown)


def on_page_content(html: str, page, config, files) -> str:
    """The docstrings' Sphinx roles as code: the name, its last part where it starts with ~."""
    return SPHINX_ROLE.sub(lambda m: f"<code>{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}</code>", html)
