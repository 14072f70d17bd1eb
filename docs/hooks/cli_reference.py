"""mkdocs hook: the flags of every ``teleop`` subcommand, generated from the argument parser at build time.

A page holding the line ``<!-- cli-reference -->`` gets, in its place, one section per subcommand of
:func:`live.cli.build_parser` (the parser the program itself uses) with its usage line and a table of
its arguments: flag, value, default and help text. A flag added to the program appears on the next
build.
"""
from __future__ import annotations

import argparse
from typing import Any

MARKER = "<!-- cli-reference -->"


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|").replace("<", "&lt;").replace("*", "\\*")


def _row(action: argparse.Action) -> str | None:
    if isinstance(action, argparse._HelpAction):
        return None
    name = ", ".join(f"`{s}`" for s in action.option_strings) or f"`{action.metavar or action.dest}`"
    if action.nargs == 0:
        value = ""
    elif action.choices:
        value = " \\| ".join(f"`{c}`" for c in action.choices)
    else:
        value = f"`{action.metavar or action.dest.upper()}`"
        if action.nargs == "?":
            value += " (optional)"
    shown = "" if action.default in (None, False, argparse.SUPPRESS) or action.nargs == 0 else f"`{action.default}`"
    if action.required:
        shown = "(required)"
    return f"| {name} | {value} | {shown} | {_cell(action.help or '')} |"


def markdown() -> str:
    """One section per subcommand: what it does, its usage line and its arguments."""
    from live.cli import build_parser
    top = build_parser([])
    helps = {a.dest: a.help for a in top._subparsers._group_actions[0]._choices_actions} if top._subparsers else {}
    parts = []
    for name in _subparsers(top):
        sub = _subparsers(build_parser([name]))[name]     # the full parser: analyze and devices load lazily
        usage = " ".join(sub.format_usage().split())
        if usage.startswith("usage: "):
            usage = usage[len("usage: "):]
        rows = [r for r in (_row(a) for a in sub._actions) if r]
        parts.append(f"\n## `teleop {name}`\n\n{_cell(helps.get(name, ''))}\n\n```\n{usage}\n```\n")
        if rows:
            parts.append("| argument | value | default | meaning |\n|---|---|---|---|\n" + "\n".join(rows) + "\n")
    return "\n".join(parts)


def on_page_markdown(text: str, page: Any, config: Any, files: Any) -> str:
    """mkdocs event: put the generated sections in place of the marker line."""
    if MARKER not in text:
        return text
    return text.replace(MARKER, markdown())
