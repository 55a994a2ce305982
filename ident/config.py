"""Typed, validated configuration from plain mappings (parsed YAML).

Every field of a config dataclass may carry metadata ``{"min": .., "max": .., "gt": ..,
"choices": .., "inf_ok": True, "max_len": .., "len": ..}``; :func:`build` checks types, ranges,
list lengths and unknown keys and raises a ValueError naming the source, the key and what is
allowed. Every number must be finite unless its field says ``inf_ok``. Reading the file is the
caller's job (the CLIs); :func:`parse_yaml` turns its text into plain data with bounds: no
aliases or anchors (an alias bomb expands a few hundred bytes into gigabytes), nesting at most
``MAX_DEPTH`` deep, no key given twice in one mapping (YAML would keep the last, silently).
"""

from __future__ import annotations

import math
import types
import typing
from dataclasses import MISSING, fields, is_dataclass
from typing import Any, TypeVar

import yaml

T = TypeVar("T")
MAX_DEPTH = 32


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader without aliases and anchors, and with a nesting limit."""

    def compose_node(self, parent, index):  # noqa: D401 - PyYAML API
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise yaml.composer.ComposerError(None, None, "aliases (*name) are not allowed", event.start_mark)
        if getattr(event, "anchor", None) is not None:
            raise yaml.composer.ComposerError(None, None, "anchors (&name) are not allowed", event.start_mark)
        depth = getattr(self, "_depth", 0) + 1
        if depth > MAX_DEPTH:
            raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels", event.start_mark)
        self._depth = depth
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth = depth - 1

    def construct_mapping(self, node, deep=False):  # noqa: D401 - PyYAML API
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, (str, int, float, bool)):  # (an unhashable key is PyYAML's own error below)
                if key in seen:
                    raise yaml.constructor.ConstructorError(None, None, f"key '{key}' given twice (which one was "
                                                            "meant?)", key_node.start_mark)
                seen.add(key)
        return super().construct_mapping(node, deep)


def parse_yaml(text: str, source: str) -> Any:
    """YAML text to plain data (safe types only, no aliases or anchors, nesting <= MAX_DEPTH); a
    ValueError naming ``source`` and the line otherwise."""
    try:
        return yaml.load(text, Loader=_BoundedLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        what = " ".join(str(getattr(exc, "problem", None) or exc).split())
        raise ValueError(f"{source}: not valid YAML{where}: {what}") from None
    except RecursionError:
        raise ValueError(f"{source}: nested too deeply (at most {MAX_DEPTH} levels)") from None


def _type_name(tp: Any) -> str:
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(tp, str(tp))


def _convert(value: Any, tp: Any, where: str, source: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], where, source)
    if tp is Any:
        return value
    if origin in (tuple, list):
        (inner, *_) = typing.get_args(tp) or (Any,)
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{source}: {where} must be a list, got {_short(value)}")
        return tuple(_convert(v, inner, f"{where}[{i}]", source) for i, v in enumerate(value))
    if is_dataclass(tp):
        return build(tp, value, source, where)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            if isinstance(value, str):
                text = value.strip().lower()
                if text in ("inf", ".inf", "+.inf", "infinity"):
                    return math.inf
                try:  # PyYAML reads 3.0e6 (no sign in the exponent, YAML 1.1) as a string
                    number = float(text)
                except ValueError:
                    pass
                else:
                    if not math.isnan(number):
                        return number
            raise ValueError(f"{source}: {where} must be a number, got {_short(value)}")
        try:
            return float(value)
        except OverflowError:  # an integer beyond a float's range
            return math.inf if value > 0 else -math.inf
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{source}: {where} must be an integer, got {_short(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{source}: {where} must be true or false, got {_short(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{source}: {where} must be a string, got {_short(value)}")
        return value
    return value


def build(cls: type[T], data: Any, source: str, prefix: str = "") -> T:
    """Instantiate dataclass ``cls`` from ``data`` (a mapping), validating every key."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(f"{source}: {prefix or 'the top level'} must be a mapping of keys to values, "
                         f"got {_short(data)}")
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in fields(cls) if f.init}
    unknown = [k for k in data if k not in known]
    if unknown:
        key = str(unknown[0]).encode("unicode_escape").decode("ascii")  # a newline in a key stays one line
        key = key if len(key) <= 40 else key[:37] + "..."
        where = f"{prefix}.{key}" if prefix else key
        raise ValueError(f"{source}: unknown key '{where}'; allowed: {', '.join(known)}")
    kwargs = {}
    for name, f in known.items():
        where = f"{prefix}.{name}" if prefix else name
        if name not in data:
            if f.default is MISSING and f.default_factory is MISSING:
                raise ValueError(f"{source}: missing key '{where}'")
            continue
        value = _convert(data[name], hints[name], where, source)
        meta = f.metadata
        if isinstance(value, tuple):
            if "len" in meta and len(value) != meta["len"]:
                raise ValueError(f"{source}: {where} must hold {meta['len']} values, got {len(value)}")
            if len(value) > meta.get("max_len", 1000):
                raise ValueError(f"{source}: {where} holds {len(value)} values; at most {meta.get('max_len', 1000)}")
        for v in value if isinstance(value, tuple) else (value,):
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                if math.isnan(v):
                    raise ValueError(f"{source}: {where} is NaN; give a number")
                if math.isinf(v) and not meta.get("inf_ok"):
                    raise ValueError(f"{source}: {where} = {v} is not finite; give a finite number")
                if "min" in meta and v < meta["min"]:
                    raise ValueError(f"{source}: {where} = {v} is out of range; allowed: >= {meta['min']}")
                if "gt" in meta and v <= meta["gt"]:
                    raise ValueError(f"{source}: {where} = {v} is out of range; allowed: > {meta['gt']}")
                if "max" in meta and v > meta["max"]:
                    raise ValueError(f"{source}: {where} = {v} is out of range; allowed: <= {meta['max']}")
            if "choices" in meta and v not in meta["choices"]:
                raise ValueError(f"{source}: {where} = {v!r} is not allowed; allowed: "
                                 f"{', '.join(map(str, meta['choices']))}")
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ValueError as exc:  # a check across fields (__post_init__)
        raise ValueError(f"{source}: {exc}") from None


def _short(value: Any, limit: int = 60) -> str:
    """repr of a value, cut for a one-line message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def to_mapping(obj: Any) -> Any:
    """A config dataclass back to plain data (for metadata, attachments, reports)."""
    if is_dataclass(obj):
        return {f.name: to_mapping(getattr(obj, f.name)) for f in fields(obj) if f.init}
    if isinstance(obj, tuple):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, float) and math.isinf(obj):
        return "inf"
    return obj
