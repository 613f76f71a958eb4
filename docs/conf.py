"""Sphinx configuration of the workbench's documentation (``make docs``).

The pages are Markdown (MyST).  The command-line reference is generated from the
argument parsers at build time by the ``orthoglide-help`` directive below, so it cannot
go stale.  The API page (``api.md``) is autodoc of the public classes only, so the build
imports the workflow, the study and the envs, not every module.
"""

from __future__ import annotations

import sys
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

project = "Orthoglide calibration workbench"
author = "the Orthoglide workbench authors"
extensions = ["myst_parser", "sphinx.ext.autodoc"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]
html_theme = "furo"
html_title = project
# "## Designed experiments" is reached as agents.md#designed-experiments, as on GitHub.
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence"]


class OrthoglideHelp(Directive):
    """``{orthoglide-help}``: every command's ``--help``, from the parsers themselves."""

    def run(self) -> list[nodes.Node]:
        import argparse

        from calibrators.cli import build_parser

        top = build_parser()
        sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
        out: list[nodes.Node] = []
        for name, parser in sub.choices.items():
            section = nodes.section(ids=[f"cli-{name}"])
            section += nodes.title(text=f"orthoglide {name}")
            help_text = parser.format_help()
            section += nodes.literal_block(help_text, help_text, language="text")
            out.append(section)
        return out


def setup(app) -> dict[str, bool]:
    app.add_directive("orthoglide-help", OrthoglideHelp)
    return {"parallel_read_safe": True}
