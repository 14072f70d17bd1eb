"""The strict YAML reader of every configuration file (configs, tools, bimanual files), with its limits.

:func:`read_yaml` reads one file into plain data and the line of each dotted key. Scalars follow the YAML
1.2 core schema (``2.0e6`` and ``1e-3`` are floats, only true/false are booleans, integers are decimal).
Hostile or absurd input ends in one :class:`~teleop.errors.ConfigError` line naming the file, the line and
column, and the dotted key where there is one, within a fraction of a second, because the limits apply while
the file is read and parsed, not after:

* :data:`MAX_BYTES`: a larger file is refused from its size, before it is read;
* :data:`MAX_DEPTH`: lists and mappings nest at most this deep (checked as each one opens, so a
  20,000-deep ``[[[...`` never reaches Python's recursion limit);
* :data:`MAX_ALIASES`: at most this many aliases (``*name``); an alias inside its own anchor is refused;
* :data:`MAX_NODES`: the document, each alias expanded to its anchor's content, holds at most this many
  values, so a few hundred bytes of nested aliases ("billion laughs") end at the first alias past it;
* a key is a plain value (a list or mapping as a key is refused at its line);
* :data:`MAX_INT_DIGITS`: an integer has at most this many digits; a value no constructor accepts (a date
  that is not one, a tag's malformed value) is refused at its line with the key it belongs to.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.error import Mark, MarkedYAMLError
from yaml.events import AliasEvent, CollectionStartEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode
from yaml.resolver import Resolver

from teleop.errors import ConfigError
from teleop.recording.text_files import text_problem

__all__ = ["MAX_BYTES", "MAX_DEPTH", "MAX_ALIASES", "MAX_NODES", "MAX_INT_DIGITS", "read_yaml"]

#: [B] largest config file read (256 KiB: 12 times the fully commented configs/default.yaml; libyaml scans 256 KiB
#: of the costliest text in about 0.01 s of a 2-core VM's processor, the pure-Python fallback in about 0.7 s)
MAX_BYTES = 256 * 1024
#: deepest nesting of lists and mappings (the shipped configs nest at most 10 deep)
MAX_DEPTH = 64
#: most aliases in one file (the shipped configs use none)
MAX_ALIASES = 100
#: most values (scalars, lists, mappings, keys included) in one file with its aliases expanded: the largest
#: shipped config (notes-bimanual.yaml) holds 736, a bimanual file of two 16-joint arms spelled out about
#: 3,500; composing 10,000 (in Python, the limits kept as it goes) takes about 0.1 s
MAX_NODES = 10_000
#: libyaml's refusal of a flow collection nested past its own limit (1000 levels): a ``[[[...`` deeper than that
#: reaches it while the scanner looks ahead for a key, before the composer counts :data:`MAX_DEPTH`
_LIBYAML_DEPTH = "exceeded maximum nesting depth"
#: most digits of an integer (a 64-bit seed has 20; every other integer setting is far smaller)
MAX_INT_DIGITS = 64


class _Refused(MarkedYAMLError):
    """A limit or a value refused while reading: ``problem`` says what, at ``problem_mark``; ``key`` is the
    dotted key it belongs to ("" unknown); ``node`` the node a constructor refused (None while composing)."""

    def __init__(self, problem: str, mark: Mark | None, key: str = "", node: Node | None = None):
        super().__init__(problem=problem, problem_mark=mark)
        self.key, self.node = key, node


def _dotted(parts: list[str]) -> str:
    """``["rig", "simulated", "[0]"]`` -> ``rig.simulated[0]``; a deep path is cut after its fourth part."""
    out = ""
    for p in parts[:4] if len(parts) > 6 else parts:
        out += p if p.startswith("[") or not out else f".{p}"
    return out if len(parts) <= 6 else f"{out}...({len(parts)} levels)"


if yaml.__with_libyaml__:
    from yaml.cyaml import CParser

    class _Events(CParser, Composer, SafeConstructor, Resolver):
        """libyaml's scanner and parser (C: 4 to 70 times the pure-Python ones' speed on the costliest files under the
        caps) under PyYAML's composer and safe constructor (Python): the parser hands out one event at a time, and
        :class:`_Loader` keeps the limits as it composes them."""

        check_node = Composer.check_node
        get_node = Composer.get_node
        get_single_node = Composer.get_single_node

        def __init__(self, stream: str):
            CParser.__init__(self, stream)
            Composer.__init__(self)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
else:                           # a PyYAML built without libyaml: every stage in Python, the same limits
    _Events = yaml.SafeLoader   # type: ignore[misc,assignment]


class _Loader(_Events):
    """A SafeLoader with the YAML 1.2 core scalars (module docstring) that keeps the limits as it composes."""

    def __init__(self, stream: str):
        super().__init__(stream)
        self._path: list[str] = []        # the key of the node being composed, one part per level
        self._depth = 0                   # lists and mappings open around it
        self._aliases = 0
        self._total = 0                   # values so far, aliases expanded
        self._sizes: dict[int, int] = {}  # id(anchored node) -> its values, aliases expanded

    def _refuse(self, problem: str, mark: Mark | None) -> _Refused:
        return _Refused(problem, mark, _dotted(self._path))

    def _count(self, n: int, mark: Mark | None) -> None:
        self._total += n
        if self._total > MAX_NODES:
            raise self._refuse(f"more than {MAX_NODES} values (an alias counts its anchor's); a config holds at "
                               f"most {MAX_NODES}", mark)

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        """One node, under the limits; ``index`` is the key node of a mapping's value, the position of a
        list's item, None for a mapping's key and the document's root."""
        part = str(index.value) if isinstance(index, ScalarNode) else f"[{index}]" if isinstance(index, int) else None
        if part is not None:
            self._path.append(part)
        try:
            return self._compose_limited(parent, index)
        finally:
            if part is not None:
                self._path.pop()

    def _compose_limited(self, parent: Node | None, index: Any) -> Node:
        event = self.peek_event()
        if isinstance(event, AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise self._refuse(f"more than {MAX_ALIASES} aliases; a config uses at most {MAX_ALIASES}",
                                   event.start_mark)
            node = super().compose_node(parent, index)
            size = self._sizes.get(id(node))
            if size is None:
                raise self._refuse(f"alias *{event.anchor} inside its own anchor &{event.anchor}; a config is a "
                                   f"tree, not a recursive structure", event.start_mark)
            self._count(size, event.start_mark)
        else:
            opens = isinstance(event, CollectionStartEvent)
            if opens and self._depth >= MAX_DEPTH:
                raise self._refuse(f"nested deeper than {MAX_DEPTH} levels; a config nests at most {MAX_DEPTH}",
                                   event.start_mark)
            before = self._total
            self._count(1, event.start_mark)
            self._depth += opens
            try:
                node = super().compose_node(parent, index)
            finally:
                self._depth -= opens
            if event.anchor is not None:
                self._sizes[id(node)] = self._total - before
        if isinstance(parent, MappingNode) and index is None and not isinstance(node, ScalarNode):
            kind = "list" if isinstance(node, SequenceNode) else "mapping"
            raise self._refuse(f"a {kind} as a key; a key is a name (a plain string)", event.start_mark)
        return node

    def construct_object(self, node: Node, deep: bool = False) -> Any:
        """The value of ``node``; a value its constructor refuses is a :class:`_Refused` at its line."""
        try:
            return super().construct_object(node, deep)
        except _Refused:
            raise
        except yaml.constructor.ConstructorError as e:
            raise _Refused(str(e.problem or e), e.problem_mark or node.start_mark, node=node) from None
        except (ValueError, TypeError, OverflowError) as e:
            raise _Refused(" ".join(str(e).split()) or type(e).__name__, node.start_mark, node=node) from None


def _int(loader: _Loader, node: ScalarNode) -> int:
    text = str(loader.construct_scalar(node))
    digits = len(text.lstrip("+-"))
    if digits > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {digits} digits; expected a number of at most {MAX_INT_DIGITS} digits")
    return int(text, 10)


_Loader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in rs if tag not in ("tag:yaml.org,2002:bool", "tag:yaml.org,2002:float",
                                                   "tag:yaml.org,2002:int")]
    for ch, rs in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                              list("tTfF"))
_Loader.add_implicit_resolver("tag:yaml.org,2002:int", re.compile(r"^[-+]?[0-9]+$"), list("-+0123456789"))
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
               r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"), list("-+0123456789."))
_Loader.add_constructor("tag:yaml.org,2002:int", _int)


class _HexLoader(_Loader):
    """:class:`_Loader` that also reads hexadecimal integers (``0xC000``: the usages and reports of device files)."""


def _hex_or_decimal(loader: _Loader, node: ScalarNode) -> int:
    text = str(loader.construct_scalar(node))
    if text.lstrip("+-")[:2].lower() != "0x":
        return _int(loader, node)
    if len(text) > MAX_INT_DIGITS:
        raise ValueError(f"an integer of {len(text)} characters; expected at most {MAX_INT_DIGITS}")
    return int(text, 16)


_HexLoader.yaml_implicit_resolvers = {ch: list(rs) for ch, rs in _Loader.yaml_implicit_resolvers.items()}
_HexLoader.add_implicit_resolver("tag:yaml.org,2002:int", re.compile(r"^[-+]?0[xX][0-9a-fA-F]+$"), list("-+0"))
_HexLoader.add_constructor("tag:yaml.org,2002:int", _hex_or_decimal)


def _line_map(root: Node | None, source: str) -> tuple[dict[str, int], dict[int, str]]:
    """(line of each dotted key, dotted key of each node by id); a duplicate key is refused (PyYAML keeps the
    last silently). The walk is bounded by the limits the composer kept (:data:`MAX_NODES`, :data:`MAX_DEPTH`)."""
    lines: dict[str, int] = {}
    keys: dict[int, str] = {}
    stack: list[tuple[Node, str]] = [] if root is None else [(root, "")]
    while stack:
        node, path = stack.pop()
        keys.setdefault(id(node), path)
        children: list[tuple[Node, str]] = []
        if isinstance(node, MappingNode):
            seen = set()
            for k, v in node.value:
                p = f"{path}.{k.value}" if path else str(k.value)
                if k.value in seen:
                    raise ConfigError(f"{source}:{k.start_mark.line + 1}: duplicate key '{p}'")
                seen.add(k.value)
                lines[p] = k.start_mark.line + 1
                children.append((v, p))
        elif isinstance(node, SequenceNode):
            for i, item in enumerate(node.value):
                lines[f"{path}[{i}]"] = item.start_mark.line + 1
                children.append((item, f"{path}[{i}]"))
        stack.extend(reversed(children))    # in the file's order: the first duplicate is the one named
    return lines, keys


def _open_text(path: Path) -> str:
    """The text of the config file at ``path``; not a regular file, larger than :data:`MAX_BYTES`, unreadable
    or not UTF-8: ConfigError naming it."""
    source = str(path)
    if path.is_dir():
        raise ConfigError(f"{source}: is a directory; expected a config file (YAML)")
    if not path.exists():
        raise ConfigError(f"{source}: config file not found (looked for {path.resolve()})")
    if not path.is_file():
        raise ConfigError(f"{source}: not a regular file; expected a config file (YAML)")
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise ConfigError(f"{source}: {size} bytes; a config file is at most {MAX_BYTES} bytes")
        with path.open("rb") as f:
            raw = f.read(MAX_BYTES + 1)     # a file that grew since: still no more than the cap
        if len(raw) > MAX_BYTES:
            raise ConfigError(f"{source}: more than {MAX_BYTES} bytes; a config file is at most {MAX_BYTES} bytes")
    except OSError as e:
        raise ConfigError(f"{source}: cannot read config file ({e})") from None
    problem = text_problem(raw)         # UTF-16, binary data, another encoding: named with the byte and line
    if problem is not None:
        what, line = problem
        raise ConfigError(f"{source}{'' if line is None else f':{line}'}: not a UTF-8 text file ({what}); "
                          "save it as UTF-8")
    return raw.decode("utf-8")


def read_yaml(path: Path, *, hex_integers: bool = False) -> tuple[Any, dict[str, int]]:
    """Read the YAML file at ``path`` under the limits of the module docstring; ``hex_integers``: ``0x...`` is an
    integer too (device files), else a string.

    Returns
    -------
    (data, lines)
        The plain data (dicts, lists, str, int, float, bool, None) and the line (1-based) of each dotted
        key (``rig.rate_hz``, ``sheath.runs[0].length``).

    Raises
    ------
    ConfigError
        Missing, not a regular file (a directory), larger than :data:`MAX_BYTES`, unreadable or not UTF-8;
        a YAML syntax error; a limit passed; a list or mapping as a key; a duplicate key; a value no
        constructor accepts. The message starts with ``<file>:<line>:<column>:`` where there is a line.
    """
    source = str(path)
    text = _open_text(path)
    loader = (_HexLoader if hex_integers else _Loader)(text)
    keys: dict[int, str] = {}
    try:
        root = loader.get_single_node()
        lines, keys = _line_map(root, source)
        data = None if root is None else loader.construct_document(root)
        return data, lines
    except ConfigError:
        raise
    except _Refused as e:
        mark = e.problem_mark
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        key = e.key or (keys.get(id(e.node), "") if e.node is not None else "")
        raise ConfigError(f"{where}: {key + ': ' if key else ''}{e.problem}") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        problem = getattr(e, "problem", None) or str(e)
        if problem == _LIBYAML_DEPTH:    # libyaml's scanner met its own limit while it looked ahead for a key
            raise ConfigError(f"{where}: nested deeper than {MAX_DEPTH} levels; a config nests at most "
                              f"{MAX_DEPTH}") from None
        raise ConfigError(f"{where}: YAML syntax error: {problem}") from None
    except (ValueError, TypeError, OverflowError, RecursionError) as e:   # a constructor's, outside any node
        raise ConfigError(f"{source}: cannot read config file ({type(e).__name__}: {e})") from None
    finally:
        loader.dispose()
