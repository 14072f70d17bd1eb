"""mkdocs hook: the configuration reference, generated from the schema at build time.

A page holding the line ``<!-- config-reference -->`` gets, in its place, one table per top-level
section of the configuration: every key (``[]`` stands for any list index), its default, unit,
valid range and meaning. The keys, defaults and types come from the dataclasses of
:mod:`teleop.config.schema`, the ranges and units from ``teleop.config.ranges.RANGES`` and the effect catalogue
(:func:`teleop.config.effects.effect_ranges`), the meanings from the comments of
``configs/default.yaml`` (else the field's comment in ``teleop/config/schema.py``). Nothing is written by
hand, so the page cannot drift from the code: a key added to the schema appears on the next build.
"""
from __future__ import annotations

import dataclasses
import math
import re
import typing
from collections.abc import Iterator
from pathlib import Path
from typing import Any

MARKER = "<!-- config-reference -->"
ROOT = Path(__file__).resolve().parents[2]
_KEY = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*):(.*)$")
_UNIT = re.compile(r"\[([^\]]{1,16})\]")
# a key without a comment of its own takes the meaning of the key it mirrors
_MIRRORS = {"instrument.joints.tendons.a.": "sheath.", "instrument.joints.tendons.b.": "sheath.",
            "rig.simulated.joints.load.": "rig.simulated.load."}


def yaml_comments(path: Path) -> dict[str, str]:
    """Dotted key -> the comment on its line in a commented YAML file (``[]`` not used: list items skipped)."""
    out: dict[str, str] = {}
    stack: list[tuple[int, str]] = []
    last, column = "", -1        # the key of the last commented line, the column of its '#'
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.lstrip().startswith("#"):
            text = line.strip()[1:].strip()
            if last and line.index("#") == column and not re.match(r"^\w+:\s", text):
                out[last] += " " + text
            else:
                last = ""    # a listing of sub-keys or a block comment: not part of the meaning
            continue
        m = _KEY.match(line)
        last = ""
        if not m:
            continue
        indent, name, rest = len(m.group(1)), m.group(2), m.group(3)
        while stack and stack[-1][0] >= indent:
            stack.pop()
        stack.append((indent, name))
        comment = rest.split("#", 1)[1].strip() if "#" in rest else ""
        key = ".".join(n for _, n in stack)
        out[key] = comment
        if comment:
            last, column = key, line.index("#")
    return out


def schema_comments(path: Path) -> dict[tuple[str, str], str]:
    """(class name, field name) -> the trailing comment of that field's line in the schema's source."""
    out: dict[tuple[str, str], str] = {}
    cls = ""
    for line in path.read_text(encoding="utf-8").splitlines():
        c = re.match(r"^class (\w+)", line)
        if c:
            cls = c.group(1)
            continue
        f = re.match(r"^    (\w+): [^#]*#\s*(.*)$", line)
        if f and cls:
            out[(cls, f.group(1))] = f.group(2).strip()
    return out


def _show(v: Any) -> str:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return "{" + ", ".join(f"{f.name}: {_show(getattr(v, f.name))}" for f in dataclasses.fields(v)) + "}"
    if isinstance(v, tuple):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and math.isinf(v):
        return ".inf"
    return str(v)


def _default(f: dataclasses.Field, owner: Any) -> Any:
    if owner is not None:
        return getattr(owner, f.name)
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def walk(cls: type, prefix: str, owner: Any) -> Iterator[tuple[str, Any, Any, str]]:
    """(dotted key, type, default, schema class name) of every leaf setting under ``cls``."""
    from teleop.config.effects import EffectsConfig
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        key, tp = f"{prefix}{f.name}", hints[f.name]
        value = _default(f, owner)
        args = typing.get_args(tp)
        elem = args[0] if typing.get_origin(tp) is tuple and args else None
        if tp is EffectsConfig:
            yield from _effects(key)
        elif dataclasses.is_dataclass(tp):
            yield from walk(tp, key + ".", value)
        elif elem is not None and dataclasses.is_dataclass(elem):
            yield key, tp, value, cls.__name__
            yield from walk(elem, key + "[].", None)
        else:
            yield key, tp, value, cls.__name__


def _effects(key: str) -> Iterator[tuple[str, Any, Any, str]]:
    from teleop.config.effects import switch_entries
    for name, entry in switch_entries().items():
        yield f"{key}.{name}.enabled", bool, False, f"effect:{entry.switch.summary}"
        for s in entry.switch.settings:
            yield f"{key}.{name}.{s.name}", float, s.default, f"effect:{s.meaning}"


def _allowed(tp: Any) -> str:
    if typing.get_origin(tp) is typing.Literal:
        return "one of: " + ", ".join(f"`{a}`" for a in typing.get_args(tp))
    if tp is bool:
        return "`true`, `false`"
    return ""


def _mirrored(plain: str, yaml: dict[str, str]) -> str:
    for mirror, to in _MIRRORS.items():
        if plain.startswith(mirror):
            return yaml.get(to + plain[len(mirror):], "")
    return ""


def _tidy(comment: str) -> str:
    """A schema comment without its leading unit and range (they have their own columns)."""
    text = comment if comment.startswith("[A-Z") else re.sub(r"^\[[^\]]*\]\s*", "", comment)
    text = re.sub(r"^(>=?|<=?)\s*[-0-9.]+\s*[,:]?\s*", "", text)
    return text


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ").replace("<", "&lt;").replace("*", "\\*")


def rows() -> list[tuple[str, str, str, str, str]]:
    """(key, default, unit, range, meaning) of every setting, in schema order."""
    from teleop.config import schema
    from teleop.config.effects import effect_ranges
    from teleop.config.ranges import RANGES
    ranges = {**RANGES, **effect_ranges()}
    yaml = yaml_comments(ROOT / "configs" / "default.yaml")
    source = schema_comments(ROOT / "teleop" / "config" / "schema.py")
    out = []
    for key, tp, default, owner in walk(schema.Config, "", schema.Config()):
        rule, unit = ranges.get(key) or ranges.get(key + "[]", ("", ""))
        plain = key.replace("[]", "")
        if owner.startswith("effect:"):
            meaning = owner[len("effect:"):]
        else:
            meaning = (yaml.get(plain) or _tidy(source.get((owner, key.rsplit(".", 1)[-1]), ""))
                       or _mirrored(plain, yaml))
        if not unit:
            m = _UNIT.search(meaning)
            unit = m.group(1) if m and "-Z" not in m.group(1) else ""
        shown = "(required)" if default is dataclasses.MISSING else f"`{_show(default)}`"
        out.append((f"`{key}`", shown, unit, _cell(rule or _allowed(tp)) if rule else _allowed(tp), _cell(meaning)))
    return out


def table() -> str:
    """The Markdown of the reference: one section per top-level key."""
    parts: list[str] = []
    section = None
    for key, default, unit, rule, meaning in rows():
        top, _, rest = key.strip("`").partition(".")
        if top != section:
            section = top
            parts.append(f"\n## `{top}`\n\n| `{top}.` key | default | unit | range | meaning |\n|---|---|---|---|---|")
        parts.append(f"| `{rest}` | {default} | {unit} | {rule} | {meaning} |")
    return "\n".join(parts) + "\n"


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """mkdocs event: put the generated tables in place of the marker line."""
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, table())
