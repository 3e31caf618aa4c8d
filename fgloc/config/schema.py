"""The typed-configuration machinery every config section uses.

Convention (see docs/DEVELOPING.md, "Configuration"):

* a section is a ``@dataclass`` defined in the module that uses it (``EKFConfig`` in
  :mod:`fgloc.backends.ekf`, ``NativeConfig`` in :mod:`fgloc.frontends.native`, ...);
  its field defaults are the *only* place a default is written;
* every field is declared with :func:`setting` (a default, a one-line ``doc``, optional
  ``min``/``max``/``gt``/``lt`` range and ``choices``); nested sections with :func:`section`;
* units are in the names (``_m``, ``_s``, ``_deg``, ``_hz``); configuration angles are in
  degrees, read in radians through :class:`radians` (``compass_sigma = radians()`` beside
  ``compass_sigma_deg``);
* :func:`parse` builds a section from a YAML mapping, checking types, ranges, unknown keys
  (with a "did you mean" suggestion); every problem is one :class:`~fgloc.errors.ConfigError`
  line ``SOURCE: section.key: problem``;
* :func:`to_yaml` writes a section back as documented YAML.

No fgloc imports here except :mod:`fgloc.errors`, so any module may import this one.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import textwrap
import types
import typing
from collections.abc import Iterable, Mapping
from dataclasses import MISSING, field, fields, is_dataclass
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, overload

import yaml

from fgloc.errors import ConfigError

T = TypeVar("T")

__all__ = ["setting", "section", "radians", "optional_radians", "parse", "to_dict", "to_yaml", "with_overrides",
           "suggest", "unknown_key_error", "check_keys", "check_mapping"]


def setting(default: Any, doc: str, *, min: float | None = None, max: float | None = None,  # noqa: A002
            gt: float | None = None, lt: float | None = None, choices: tuple[Any, ...] | None = None,
            finite: bool = True) -> Any:
    """A documented config field: ``x_m: float = setting(0.1, "what it does", min=0)``.

    ``min``/``max`` are inclusive bounds, ``gt``/``lt`` exclusive; for tuples they apply to
    every element.  ``choices`` lists the accepted values (strings are matched exactly).  A number
    must be finite (NaN never is accepted; ``.inf`` only with ``finite=False``).
    """
    md = {"doc": doc, "min": min, "max": max, "gt": gt, "lt": lt, "choices": choices, "finite": finite}
    if isinstance(default, (list, dict, set)):
        return field(default_factory=lambda: type(default)(default), metadata=md)
    return field(default=default, metadata=md)


def section(cls: type, doc: str) -> Any:
    """A nested section (another config dataclass) with its defaults."""
    return field(default_factory=cls, metadata={"doc": doc})


class _DegreesSetting:
    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name
        self.field_deg = f"{name}_deg"

    def __set__(self, obj: object, value: object) -> None:
        raise AttributeError(f"{self.name} is {self.field_deg} in radians: set {self.field_deg}")


class radians(_DegreesSetting):  # noqa: N801 - named like setting(), used like it
    """A section's angle setting in radians, where it is used: ``compass_sigma = radians()`` in a
    section reads its ``compass_sigma_deg`` field (read-only; not a field, so not a key)."""

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> radians: ...

    @overload
    def __get__(self, obj: object, owner: type | None = None) -> float: ...

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return math.radians(getattr(obj, self.field_deg))


class optional_radians(_DegreesSetting):  # noqa: N801
    """As :class:`radians` for a setting that may be None (None stays None)."""

    @overload
    def __get__(self, obj: None, owner: type | None = None) -> optional_radians: ...

    @overload
    def __get__(self, obj: object, owner: type | None = None) -> float | None: ...

    def __get__(self, obj: object, owner: type | None = None) -> Any:
        if obj is None:
            return self
        deg = getattr(obj, self.field_deg)
        return None if deg is None else math.radians(deg)


# ------------------------------------------------------------------ helpers
def suggest(name: str, candidates: Iterable[str]) -> str:
    """`` (did you mean X?)`` for the closest candidate, or ``""``."""
    m = difflib.get_close_matches(str(name), sorted(candidates), n=1, cutoff=0.6)
    return f" (did you mean {m[0]}?)" if m else ""


def unknown_key_error(source: str, where: str, key: str, allowed: list[str] | tuple[str, ...] | set[str],
                      what: str = "key") -> ConfigError:
    path = f"{where}.{key}" if where else str(key)
    hint = suggest(str(key), allowed)
    if not hint:
        hint = f" (known: {', '.join(sorted(allowed))})"
    return ConfigError(f"{source}: {path}: unknown {what}{hint}")


def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _describe(tp: Any) -> str:
    origin = get_origin(tp)
    if tp is bool:
        return "true or false"
    if tp is int:
        return "an integer"
    if tp is float:
        return "a number"
    if tp is str:
        return "a string"
    if origin is Literal:
        return "one of " + ", ".join(str(a) for a in get_args(tp))
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        out = " or ".join(_describe(a) for a in args if a is not type(None))
        return out + " or null" if type(None) in args else out
    if origin is tuple:
        args = get_args(tp)
        item = _describe(args[0]).removeprefix("a ").removeprefix("an ")
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {item}s"
        return f"a list of {len(args)} {item}s"
    if is_dataclass(tp):
        return "a mapping"
    return getattr(tp, "__name__", str(tp))


class _Bad(Exception):
    pass


def _coerce(tp: Any, value: Any) -> Any:
    """``value`` as type ``tp`` or raise :class:`_Bad` (YAML gives int for 2, list for tuples)."""
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None:
            if type(None) in args:
                return None
            raise _Bad
        # a string that is also a choice of a Literal/str member goes there; numbers first otherwise
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(a, value)
            except _Bad:
                continue
        raise _Bad
    if value is None:
        raise _Bad
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _Bad
    if tp is int:
        if isinstance(value, bool):
            raise _Bad
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise _Bad
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _Bad
        return float(value)
    if tp is str:
        if isinstance(value, str):
            return value
        raise _Bad
    if origin is Literal:
        if value in get_args(tp) and not isinstance(value, bool):
            return value
        raise _Bad
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise _Bad
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v) for v in value)
        if len(value) != len(args):
            raise _Bad
        return tuple(_coerce(a, v) for a, v in zip(args, value, strict=True))
    if origin is list:
        (a,) = get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise _Bad
        return [_coerce(a, v) for v in value]
    if origin is dict or tp is dict:
        if not isinstance(value, Mapping):
            raise _Bad
        return dict(value)
    raise _Bad


def _check_range(f: dataclasses.Field, value: Any, raw: Any = None) -> str | None:
    md = f.metadata
    shown = value if raw is None else raw
    vals = value if isinstance(value, tuple) else (value,)
    for v in vals:
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            continue
        if isinstance(v, float) and math.isnan(v):
            return "must be a number, got NaN"
        if isinstance(v, float) and math.isinf(v) and md.get("finite", True):
            return f"must be a finite number, got {_fmt(shown)}"
        if md.get("min") is not None and v < md["min"]:
            return f"must be >= {md['min']}, got {_fmt(shown)}"
        if md.get("max") is not None and v > md["max"]:
            return f"must be <= {md['max']}, got {_fmt(shown)}"
        if md.get("gt") is not None and not v > md["gt"]:
            return f"must be > {md['gt']}, got {_fmt(shown)}"
        if md.get("lt") is not None and not v < md["lt"]:
            return f"must be < {md['lt']}, got {_fmt(shown)}"
    ch = md.get("choices")
    if ch is not None and value not in ch:
        hint = suggest(str(value), [str(c) for c in ch])
        return f"must be one of {', '.join(str(c) for c in ch)}, got {_fmt(shown)}{hint}"
    return None


def _fmt(v: Any) -> str:
    """A value as its YAML (flow style), at most :data:`SHOWN_CHARS` characters."""
    if isinstance(v, tuple):
        v = list(v)
    try:
        s = yaml.safe_dump(v, default_flow_style=True, width=1000).strip()
    except (RecursionError, yaml.YAMLError):
        s = f"a {type(v).__name__} nested too deep to show"
    s = s[:-4].strip() if s.endswith("...") else s
    return s if len(s) <= SHOWN_CHARS else s[: SHOWN_CHARS - 3] + "..."


SHOWN_CHARS = 120  # a wrong value is shown in an error line up to this long

#: YAML 1.2's floats (core schema): ``1e-3``, ``2E+5``, ``.5``, ``1.``, ``.inf``, ``-.Inf``, ``.nan``.
#: PyYAML reads YAML 1.1, whose floats need a dot (``1e-3`` was the string "1e-3"), while the YAML
#: of ROS 2 (yaml-cpp), map_server and most editors is 1.2.
_FLOAT_12 = re.compile(r"""^(?:[-+]?(?:\.[0-9]+|[0-9]+\.[0-9]*                         # 1.5  .5  1.
                                    |[0-9]+(?:\.[0-9]*)?[eE][-+]?[0-9]+|\.[0-9]+[eE][-+]?[0-9]+)  # 1e-3  .5E2
                           |[-+]?\.(?:inf|Inf|INF)
                           |\.(?:nan|NaN|NAN))$""", re.X)
_FLOAT_TAG = "tag:yaml.org,2002:float"


def yaml12_loader(base: Any) -> Any:
    """``base`` (a PyYAML safe loader) reading floats as YAML 1.2 does (ints and the rest as before)."""
    loader: Any = type(f"Yaml12{base.__name__}", (base,), {})
    loader.yaml_implicit_resolvers = {
        first: [(tag, rx) for tag, rx in rules if tag != _FLOAT_TAG]
        for first, rules in base.yaml_implicit_resolvers.items()}
    loader.add_implicit_resolver(_FLOAT_TAG, _FLOAT_12, list("-+0123456789."))
    return loader


_LOADERS: list[Any] = []


def load_yaml(text: str, loader: Any = None) -> Any:
    """A user's YAML (config files, scenarios, maps, manifests, ROS parameter files), safely: floats as
    YAML 1.2 reads them (``1e-3`` is a number), and a document nested deeper than Python can follow a
    :class:`yaml.YAMLError` like any other unreadable YAML (never a RecursionError).  Errors are
    ``yaml.YAMLError``: the caller names its file.  ``loader``: another (a :func:`yaml12_loader`)."""
    if not _LOADERS:
        _LOADERS.append(yaml12_loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)))
    try:
        return yaml.load(text, Loader=loader or _LOADERS[0])  # noqa: S506 - a safe loader
    except RecursionError:
        raise yaml.YAMLError("nested too deeply to read") from None


# ------------------------------------------------------------------ parse
def check_mapping(data: Any, source: str, where: str) -> Mapping[str, Any]:
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        return _raise(source, where, f"expected a mapping of keys, got {_fmt(data)}")
    return data


def _raise(source: str, where: str, problem: str) -> Any:
    raise ConfigError(f"{source}: {where}: {problem}" if where else f"{source}: {problem}")


def parse(cls: type[T], data: Any, source: str = "config", where: str = "", base: T | None = None) -> T:
    """Build section ``cls`` from a YAML mapping ``data`` overlaid on ``base`` (default: the defaults).

    Keys left out keep their value; unknown keys, wrong types and values out of range raise a
    one-line :class:`ConfigError` ``SOURCE: where.key: problem``.
    """
    mapping = check_mapping(data, source, where)
    cur = base if base is not None else cls()
    hints = _hints(cls)
    by_name = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    updates: dict[str, Any] = {}
    for key, value in mapping.items():
        f = by_name.get(str(key))
        if f is None:
            raise unknown_key_error(source, where, str(key), list(by_name))
        path = f"{where}.{key}" if where else str(key)
        tp = hints[f.name]
        if is_dataclass(tp):
            if isinstance(value, tp):  # type: ignore[arg-type]
                updates[f.name] = value
            else:
                updates[f.name] = parse(tp, value, source, path, getattr(cur, f.name))  # type: ignore[arg-type]
            continue
        try:
            v = _coerce(tp, value)
        except _Bad:
            _raise(source, path, f"expected {_describe(tp)}, got {_fmt(value)}")
        problem = _check_range(f, v, value)
        if problem:
            _raise(source, path, problem)
        updates[f.name] = v
    try:
        out = dataclasses.replace(cur, **updates)  # type: ignore[type-var]
    except ConfigError as e:  # a __post_init__ cross-check: name the file
        raise ConfigError(f"{source}: {where}: {e}" if where else f"{source}: {e}") from None
    return out


def with_overrides(cls: type[T], config: T | None, overrides: Mapping[str, Any]) -> T:
    """``config`` (or the defaults) with keyword ``overrides`` (checked like YAML values)."""
    base = config if config is not None else cls()
    if not overrides:
        return base
    return parse(cls, dict(overrides), source=cls.__name__, base=base)


# ------------------------------------------------------------------ dump
def _plain(v: Any) -> Any:
    if is_dataclass(v) and not isinstance(v, type):
        return to_dict(v)
    if isinstance(v, tuple):
        return [_plain(x) for x in v]
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return float(v)
    return v


def to_dict(obj: Any) -> dict[str, Any]:
    """A section as plain YAML-ready data (tuples as lists, nested sections as mappings)."""
    return {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}


def _doc_of(f: dataclasses.Field) -> str:
    md = f.metadata
    doc = str(md.get("doc") or "")
    extra = []
    if md.get("choices") is not None:
        extra.append(" | ".join(str(c) for c in md["choices"]))
    for k, sym in (("min", ">="), ("gt", ">"), ("max", "<="), ("lt", "<")):
        if md.get(k) is not None:
            extra.append(f"{sym} {md[k]}")
    if extra:
        doc = f"{doc} [{', '.join(extra)}]" if doc else f"[{', '.join(extra)}]"
    return doc


def _emit(obj: Any, indent: int, lines: list[str], comments: bool, defaults: Any = None) -> None:
    pad = "  " * indent
    hints = _hints(type(obj))
    for f in fields(obj):
        v = getattr(obj, f.name)
        doc = _doc_of(f) if comments else ""
        if comments and doc:
            for ln in textwrap.wrap(doc, width=max(40, 96 - len(pad))):
                lines.append(f"{pad}# {ln}")
        if is_dataclass(hints.get(f.name)):
            lines.append(f"{pad}{f.name}:")
            _emit(v, indent + 1, lines, comments)
            continue
        val = _fmt(_plain(v))
        lines.append(f"{pad}{f.name}: {val}")


def to_yaml(obj: Any, comments: bool = True, header: str = "") -> str:
    """``obj`` (a section or the whole config) as YAML; with ``comments`` each key's doc above it."""
    lines: list[str] = []
    if header:
        lines.extend(f"# {ln}" if ln else "#" for ln in header.splitlines())
        lines.append("")
    first = True
    hints = _hints(type(obj))
    for f in fields(obj):
        v = getattr(obj, f.name)
        if not first and comments:
            lines.append("")
        first = False
        if comments and f.metadata.get("doc"):
            for ln in textwrap.wrap(str(f.metadata["doc"]), width=96):
                lines.append(f"# {ln}")
        if is_dataclass(hints.get(f.name)):
            lines.append(f"{f.name}:")
            _emit(v, 1, lines, comments)
        else:
            lines.append(f"{f.name}: {_fmt(_plain(v))}")
    return "\n".join(lines) + "\n"


def field_default(cls: type, name: str) -> Any:
    """The declared default of ``cls.name`` (for code that needs one value, e.g. a CLI default)."""
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name == name:
            if f.default is not MISSING:
                return f.default
            if f.default_factory is not MISSING:
                return f.default_factory()
    raise KeyError(name)


def check_keys(data: Any, template: Mapping[str, Any], source: str, where: str = "",
               open_keys: tuple[str, ...] = ()) -> None:
    """Check a loosely typed mapping (a simulator scenario) against a template of its keys.

    Every key of ``data`` must be a key of ``template`` ("did you mean" otherwise); where the
    template's value is a mapping and so is the data's, the check recurses; a template value
    that is a list holding one mapping checks every item of the data's list against it.
    Keys in ``open_keys`` (dotted paths) are not checked below.
    """
    mapping = check_mapping(data, source, where)
    for key, value in mapping.items():
        if str(key) not in template:
            raise unknown_key_error(source, where, str(key), [str(k) for k in template])
        path = f"{where}.{key}" if where else str(key)
        if path in open_keys:
            continue
        sub = template[key]
        if isinstance(sub, Mapping) and isinstance(value, Mapping):
            check_keys(value, sub, source, path, open_keys)
        elif isinstance(sub, list) and len(sub) == 1 and isinstance(sub[0], Mapping):
            if not isinstance(value, list):
                _raise(source, path, f"expected a list, got {_fmt(value)}")
            for i, item in enumerate(value):
                check_keys(item, sub[0], source, f"{path}[{i}]", open_keys)
