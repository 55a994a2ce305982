"""Typed, validated configuration from plain mappings (parsed YAML).

Every field of a config dataclass may carry metadata ``{"min": .., "max": ..,
"choices": ..}``; :func:`build` checks types, ranges and unknown keys and raises
a ValueError naming the source, the key and what is allowed. Reading the file
is the caller's job (the CLIs); this module only sees the parsed mapping.
"""

from __future__ import annotations

import math
import types
import typing
from dataclasses import MISSING, fields, is_dataclass
from typing import Any, TypeVar

T = TypeVar("T")


def _type_name(tp: Any) -> str:
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(tp, str(tp))


def _convert(value: Any, tp: Any, where: str, source: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], where, source)
    if origin in (tuple, list):
        (inner, *_) = typing.get_args(tp) or (Any,)
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{source}: {where} must be a list, got {value!r}")
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
            raise ValueError(f"{source}: {where} must be a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{source}: {where} must be an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ValueError(f"{source}: {where} must be true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ValueError(f"{source}: {where} must be a string, got {value!r}")
        return value
    return value


def build(cls: type[T], data: Any, source: str, prefix: str = "") -> T:
    """Instantiate dataclass ``cls`` from ``data`` (a mapping), validating every key."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(f"{source}: {prefix or 'the top level'} must be a mapping of keys to values, "
                         f"got {data!r}")
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in fields(cls) if f.init}
    unknown = [k for k in data if k not in known]
    if unknown:
        where = f"{prefix}.{unknown[0]}" if prefix else str(unknown[0])
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
        for v in value if isinstance(value, tuple) else (value,):
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                if math.isnan(v):
                    raise ValueError(f"{source}: {where} is NaN; give a number")
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
    return cls(**kwargs)


def to_mapping(obj: Any) -> Any:
    """A config dataclass back to plain data (for metadata, attachments, reports)."""
    if is_dataclass(obj):
        return {f.name: to_mapping(getattr(obj, f.name)) for f in fields(obj) if f.init}
    if isinstance(obj, tuple):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, float) and math.isinf(obj):
        return "inf"
    return obj
