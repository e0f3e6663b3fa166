"""Sphinx directives that generate varflow's reference pages from the code itself.

``.. varflow-cli::``
    The ``--help`` of every command and sub-command of the ``varflow`` parser
    (:func:`varflow.cli.build_parser`), formatted at 88 columns.
``.. varflow-parameters:: twoframe | trajectories | interpolation``
    For every method of the registry, a table of its parameters (name, flag,
    symbol, default, meaning) from :func:`varflow.cli._common.parameter_rows`, which
    reads the parameter dataclasses and their docstrings.
``api.rst``
    Written by :func:`write_api_page`, which ``conf.py`` calls before Sphinx reads the
    sources: the autosummaries of ``varflow.__all__``, ``varflow.io.video.__all__``, the
    registries and every registered method's parameter class.

Generated at build time, so the pages cannot drift from the code.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx.util.nodes import nested_parse_with_titles

#: Width of the generated help texts.
HELP_COLUMNS = 88


def registries() -> dict[str, dict[str, Any]]:
    """The method registries by kind: two-frame flow, trajectories, interpolation,
    restoration (denoisers), repair (the stages of ``varflow restore``)."""
    from varflow.registry import FLOW, INTERPOLATE, REPAIR, RESTORE, TRACK

    return {"twoframe": FLOW, "trajectories": TRACK, "interpolation": INTERPOLATE,
            "restoration": RESTORE, "repair": REPAIR}


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    """``(name, parser)`` of the sub-commands of ``parser``, depth first, in order."""
    out: list[tuple[str, argparse.ArgumentParser]] = []
    for action in parser._actions:  # noqa: SLF001 - argparse has no public accessor
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            for name, sub in action.choices.items():
                out.append((name, sub))
                out += [(f"{name} {n}", p) for n, p in _subcommands(sub)]
    return out


def cli_help_texts() -> list[tuple[str, str]]:
    """``(command, help text)`` of ``varflow`` and every (sub-)command."""
    from varflow.cli import build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_COLUMNS)
    try:
        parser = build_parser([])
        texts = [("varflow", parser.format_help())]
        texts += [(f"varflow {name}", sub.format_help()) for name, sub in _subcommands(parser)]
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return texts


def _rst_text(text: str) -> str:
    """``text`` (a docstring's reST) with the bars outside literals escaped: ``|∇I|`` in a
    meaning is a norm, not a substitution reference."""
    parts = text.split("``")
    for k in range(0, len(parts), 2):  # outside the ``literals``
        parts[k] = parts[k].replace("|", "\\|")
    return "``".join(parts)


def parameter_rst(kind: str) -> list[str]:
    """reST of the parameter tables of every method of one registry."""
    from varflow.cli._common import flag_of, parameter_rows

    lines: list[str] = []
    from varflow.registry import parameter_fields

    for name, entry in registries()[kind].items():
        owners = []
        for _, _, owner in parameter_fields(entry):
            if owner not in owners:
                owners.append(owner)
        classes = ", ".join(f":class:`{c.__module__}.{c.__qualname__}`" for c in owners)
        title = f"``{name}``"
        use = entry.use[:1].upper() + entry.use[1:] + "."
        lines += [title, "~" * len(title), "", entry.description[0].upper()
                  + entry.description[1:] + ".", "", f"*When to use it:* {use}" if entry.use
                  else "", "",
                  f"Parameter classes: {classes}.", "",
                  ".. list-table::", "   :header-rows: 1", "   :widths: 28 11 12 49",
                  "   :width: 100%", "   :class: varflow-params", "",
                  "   * - parameter (flag)", "     - symbol", "     - default",
                  "     - meaning"]
        for field, symbol, default, meaning in parameter_rows(name):
            flag = flag_of(name, field)
            lines += [f"   * - ``{field}`` (``{flag}``)", f"     - {symbol or '—'}",
                      f"     - ``{default}``", f"     - {_rst_text(meaning) or '—'}"]
        lines.append("")
    return lines


class _Generated(Directive):
    def render(self, lines: list[str]) -> list[nodes.Node]:
        node = nodes.section()
        node.document = self.state.document
        nested_parse_with_titles(self.state, StringList(lines, source="varflow_docs"), node)
        return node.children


class CLIReference(_Generated):
    """``.. varflow-cli::``: every command's ``--help``."""

    def run(self) -> list[nodes.Node]:
        lines: list[str] = []
        for command, text in cli_help_texts():
            title = f"``{command}``"
            lines += [title, "-" * len(title), "", ".. code-block:: text", ""]
            lines += ["   " + ln if ln else "" for ln in text.rstrip().splitlines()]
            lines.append("")
        return self.render(lines)


class ParameterTables(_Generated):
    """``.. varflow-parameters:: KIND``: the parameter tables of one registry."""

    required_arguments = 1
    option_spec: dict[str, Any] = {}

    def run(self) -> list[nodes.Node]:
        kind = self.arguments[0]
        if kind not in registries():
            raise self.error(f"varflow-parameters: unknown registry {kind!r}; expected one "
                             f"of {', '.join(registries())}")
        return self.render(parameter_rst(kind))


def api_page() -> str:
    """The API reference page: autosummaries of the public names of ``varflow`` and
    ``varflow.io.video``, the registries, and every registered method's parameter
    class, from their ``__all__`` and the registries themselves."""
    import varflow
    import varflow.io.video as video

    def summary(names: list[str]) -> list[str]:
        return [".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""] + [
            f"   {n}" for n in names] + [""]

    def title(text: str, mark: str) -> list[str]:
        return [text, mark * len(text), ""]

    from varflow.registry import parameter_fields

    classes: list[str] = []
    for registry in registries().values():
        for entry in registry.values():
            for _, _, owner in parameter_fields(entry):
                path = f"{owner.__module__}.{owner.__qualname__}"
                if path not in classes:
                    classes.append(path)
    public = [n for n in varflow.__all__ if not n.startswith("__") and n.upper() != n]
    lines = [".. This page is generated by docs/_ext/varflow_docs.py (api_page); do not edit.",
             "", ".. _api:", ""] + title("API reference", "=")
    lines += ["Every public name of :mod:`varflow` and :mod:`varflow.io.video`, the method",
              "registries and the parameter class of every registered method (generated",
              "from the code's ``__all__`` and registries at build time).", ""]
    # the sections of fully qualified names first: autosummary prefixes the names of a
    # section with the current module, and there is no current module until it is set
    lines += title("Registries", "-")
    lines += ["One registry per kind of method, which the command line, the benchmarks and",
              "these pages read: ``varflow.registry.FLOW`` (two-frame flow),",
              "``varflow.registry.TRACK`` (trajectories),",
              "``varflow.registry.INTERPOLATE`` (frame interpolation),",
              "``varflow.registry.RESTORE`` (denoising) and ``varflow.registry.REPAIR``",
              "(the repair stages of archival footage), filled by the",
              "``methods`` module of each package; parameters are composed frozen",
              "dataclasses whose flat names are routed to their owner:", ""]
    lines += summary(["varflow.registry", "varflow.parameters", "varflow.twoframe.params",
                      "varflow.twoframe.methods", "varflow.multiframe.methods",
                      "varflow.retime.methods", "varflow.restore.methods",
                      "varflow.restore.denoise", "varflow.restore.chain"])
    lines += title("Parameter classes", "-") + [
        "The frozen dataclasses of the methods' parameters and of the terms composed into",
        "them; their fields, symbols and defaults are tabled in :doc:`parameters`.",
        ""] + summary(classes)
    lines += title("varflow", "-") + [".. currentmodule:: varflow", ""] + summary(public)
    lines += title("varflow.io.video", "-") + [".. currentmodule:: varflow.io.video", ""]
    lines += summary(list(video.__all__))
    return "\n".join(lines) + "\n"


def write_api_page(srcdir: str) -> None:
    """Write ``api.rst`` into ``srcdir`` (called from ``conf.py``, before Sphinx looks for
    the sources and autosummary reads them); an unchanged page is left alone."""
    path = os.path.join(srcdir, "api.rst")
    text = api_page()
    old = None
    if os.path.exists(path):
        with open(path, encoding="utf-8") as f:
            old = f.read()
    if old != text:  # unchanged: keep the timestamp, no rebuild
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)


def setup(app: Any) -> dict[str, Any]:
    app.add_directive("varflow-cli", CLIReference)
    app.add_directive("varflow-parameters", ParameterTables)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
