"""Bounded reading of the input files: robot, problem and task files (YAML), pose files
(JSON). Whatever a file holds, reading it takes bounded time and memory and either
returns plain Python data or raises an InputError naming the file and what is wrong:

- plain numbers are read as YAML 1.2 does (``1.0e4`` is a float, as for ROS 2), quoted
  ones stay strings (and are refused where a number belongs);
- only a regular file is read (not a directory, a FIFO or a device), at most
  ``max_bytes`` of it (1 MiB for YAML, 16 MiB for a pose file); an OSError while reading
  (EIO, EACCES, ...) is an InputError;
- the text must be UTF-8 without NUL characters (a binary file is refused);
- a key given twice in one mapping (YAML or JSON) is refused, naming the key: both
  parsers would silently keep the last one;
- YAML anchors and aliases are refused (a 300-byte "billion laughs" file would expand to
  billions of nodes), and so is a document nested deeper than ``max_depth`` levels, a list
  or mapping of more than ``max_items`` entries or more than ``max_nodes`` values in all.
  These are checked on the parser's events, before any Python object is built (YAML), or
  on the parsed document (JSON, ``check_structure``; a pose file whose shape
  ``parsing.poses`` checks in bulk is within the limits by that shape and is not walked).

The limits are far above what the files of this project need (a robot file has about 150
values in 4 levels).
"""

import json
import itertools
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

import yaml

from .errors import InputError


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):
    """PyYAML's safe loader (libyaml's parser when PyYAML has it: 25x faster than the
    pure-Python one) that also reads YAML 1.2 floats such as ``1.0e4`` and ``1e-3`` as
    numbers, as ROS 2's parameter parser does (YAML 1.1 wants ``1.0e+4``). A quoted
    ``"0.1"`` stays a string."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?$"),
    list("-+0123456789."))


def _construct_unique_mapping(loader, node, deep=False):
    """SafeConstructor's mapping, refusing a key given twice (merge keys ``<<`` aside):
    PyYAML keeps the last one silently."""
    seen = set()
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            duplicate = key in seen
            seen.add(key)
        except TypeError:  # an unhashable key: SafeConstructor refuses it itself
            continue
        if duplicate:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                f"duplicate key {key!r}", key_node.start_mark)
    return yaml.constructor.SafeConstructor.construct_mapping(loader, node, deep=deep)


_Loader.construct_mapping = _construct_unique_mapping
_LOADER = _Loader


@dataclass(frozen=True)
class Limits:
    """Bounds on one input file: bytes, nesting depth, entries of one list or mapping,
    values (scalars and collections) in all."""

    max_bytes: int = 1 << 20
    max_depth: int = 32
    max_items: int = 10_000
    max_nodes: int = 100_000
    items_note: str = ""   # said after the entries bound (what it stands for, for this file)


YAML_LIMITS = Limits()
JSON_LIMITS = Limits(max_bytes=16 << 20, max_items=100_000, max_nodes=2_000_000)


def read_text(path, where, max_bytes=YAML_LIMITS.max_bytes):
    """The UTF-8 text of the regular file ``path`` (at most ``max_bytes``); InputError
    naming ``where`` otherwise."""
    return decode_text(read_bytes(path, where, max_bytes), path, where)


def read_bytes(path, where, max_bytes=YAML_LIMITS.max_bytes):
    """The bytes of the regular file ``path`` (at most ``max_bytes``), not yet known to be
    text (``decode_text``); InputError naming ``where`` otherwise."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(where, str(path), "file not found") from None
    except (OSError, ValueError) as exc:
        raise InputError(where, str(path), f"cannot read: {_strerror(exc)}") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(where, str(path), "is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(where, str(path), "not a regular file (a FIFO, socket or device?)")
    if st.st_size > max_bytes:
        raise InputError(where, str(path), f"file too large: {st.st_size} bytes "
                                           f"(at most {max_bytes})")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise InputError(where, str(path), f"cannot read: {_strerror(exc)}") from None
    if len(data) > max_bytes:
        raise InputError(where, str(path), f"file too large: over {max_bytes} bytes")
    return data


def decode_text(data, path, where):
    """``read_bytes``'s ``data`` of ``path`` as UTF-8 text without NUL characters;
    InputError naming ``where`` otherwise."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(where, str(path), f"not UTF-8 text (a binary file?): byte "
                                           f"0x{data[exc.start]:02x} at offset {exc.start}") from None
    if "\x00" in text:
        raise InputError(where, str(path), f"not text (a binary file?): NUL character at "
                                           f"offset {text.index(chr(0))}")
    return text


def _strerror(exc):
    if isinstance(exc, OSError):
        return exc.strerror or type(exc).__name__
    return str(exc)


# ----------------------------------------------------------------------------- YAML

def read_yaml(path, where, limits=YAML_LIMITS):
    """The parsed YAML file at ``path`` (one document; aliases, depth and sizes bounded)."""
    text = read_text(path, where, limits.max_bytes)
    return parse_yaml(text, where, str(path), limits)


def read_yaml_mapping(path, where, expected, limits=YAML_LIMITS):
    """The parsed YAML file at ``path`` if it is a mapping; else InputError naming ``where``
    and the file: empty, or what it holds instead (``expected``: what the mapping holds,
    e.g. "'scene:'")."""
    doc = read_yaml(path, where, limits)
    if not isinstance(doc, dict):
        held = "the file is empty" if doc is None else f"the file holds a {type(doc).__name__}"
        raise InputError(where, str(path), f"{held}; expected a mapping with {expected}")
    return doc


def parse_yaml(text, where, name="", limits=YAML_LIMITS):
    """Parse YAML ``text`` after checking its events against ``limits``; InputError
    naming ``where`` (and ``name``, the file) otherwise."""
    label = name or "<text>"
    try:
        _check_yaml_events(text, where, label, limits)
        return yaml.load(text, Loader=_LOADER)
    except InputError:
        raise
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise InputError(where, label, f"not valid YAML: {exc.problem or exc.context}{at}") from None
    except (yaml.YAMLError, ValueError, OverflowError, RecursionError, MemoryError) as exc:
        # ValueError: an integer of over 4300 digits; the rest are PyYAML's own refusals
        raise InputError(where, label, f"not valid YAML: {type(exc).__name__}: {exc}") from None


def _check_yaml_events(text, where, label, limits):
    """Walk the parser's events (no Python objects built) and refuse what breaks a limit."""
    # [entries so far, most allowed] of each open collection; a mapping's entries are
    # its keys and its values
    open_ = []
    nodes = 0
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, yaml.AliasEvent):
            _refuse(where, label, event, "YAML aliases (*name) are not allowed")
        if not isinstance(event, yaml.NodeEvent):
            if isinstance(event, yaml.CollectionEndEvent):
                open_.pop()
            continue
        if event.anchor is not None:
            _refuse(where, label, event, "YAML anchors (&name) are not allowed")
        nodes += 1
        if nodes > limits.max_nodes:
            _refuse(where, label, event, f"more than {limits.max_nodes} values")
        if open_:
            open_[-1][0] += 1
            if open_[-1][0] > open_[-1][1]:
                _refuse(where, label, event, f"a list or mapping of more than "
                                             f"{limits.max_items} entries{limits.items_note}")
        if isinstance(event, yaml.CollectionStartEvent):
            pairs = isinstance(event, yaml.MappingStartEvent)
            open_.append([0, (2 if pairs else 1) * limits.max_items])
            if len(open_) > limits.max_depth:
                _refuse(where, label, event, f"nested deeper than {limits.max_depth} levels")


def _refuse(where, label, event, reason):
    mark = event.start_mark
    at = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
    raise InputError(where, label, reason + at)


# ----------------------------------------------------------------------------- JSON

def read_json(path, where, limits=JSON_LIMITS):
    """The parsed JSON file at ``path`` (depth and sizes bounded)."""
    return parse_json_text(read_text(path, where, limits.max_bytes), where, str(path), limits)


def parse_json_text(text, where, label, limits=JSON_LIMITS):
    """The parsed JSON ``text`` of the file ``label`` (depth and sizes bounded, a key given
    twice refused): ``read_json`` once the file is read (pose files read in bulk are parsed
    otherwise first: parsing/poses.py)."""
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise InputError(where, label, f"duplicate key {exc.args[0]!r} in one object") from None
    except json.JSONDecodeError as exc:
        raise InputError(where, label, f"not valid JSON: {exc.msg} (line {exc.lineno}, "
                                       f"column {exc.colno})") from None
    except RecursionError:
        raise InputError(where, label, f"nested deeper than {limits.max_depth} levels") from None
    except ValueError as exc:  # an integer of over 4300 digits
        raise InputError(where, label, f"not valid JSON: {exc}") from None
    check_structure(doc, where, label, limits)
    return doc


class _DuplicateKey(Exception):
    """A JSON object with a key given twice (the key is args[0])."""


def _unique_keys(pairs):
    """A JSON object's dict, refusing a key given twice (json keeps the last silently)."""
    out = dict(pairs)
    if len(out) != len(pairs):
        seen = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return out


def check_structure(doc, where, label, limits):
    """Refuse plain data (lists, dicts, scalars) nested deeper than ``limits.max_depth``,
    with a collection of more than ``limits.max_items`` entries or more than
    ``limits.max_nodes`` values in all. Iterative: any depth is safe to walk."""
    stack = [(doc, 1)]
    nodes = 0
    while stack:
        value, depth = stack.pop()
        nodes += 1
        if nodes > limits.max_nodes:
            raise InputError(where, label, f"more than {limits.max_nodes} values")
        if isinstance(value, dict):
            items = list(value.values())
        elif isinstance(value, list):
            items = value
        else:
            continue
        if depth > limits.max_depth:
            raise InputError(where, label, f"nested deeper than {limits.max_depth} levels")
        if len(items) > limits.max_items:
            raise InputError(where, label, f"a list or mapping of {len(items)} entries "
                                           f"(at most {limits.max_items})")
        inner = [x for x in items if isinstance(x, (list, dict))]  # one pass: 10^5 poses
        nodes += len(items) - len(inner)
        stack.extend(zip(inner, itertools.repeat(depth + 1)))
    if nodes > limits.max_nodes:
        raise InputError(where, label, f"more than {limits.max_nodes} values")
