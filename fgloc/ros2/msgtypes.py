"""DDS data types of the ROS 2 messages fgloc exchanges, built from :mod:`fgloc.io.msgdefs`.

A DDS topic needs a type: its name (``pkg::msg::dds_::Type_``, :func:`fgloc.ros2.names.dds_type`)
is what a ROS 2 peer matches on, and Cyclone DDS publishes the type's structure (XTypes type
information) beside it.  The classes here are generated from the one copy of each message's
fields (:data:`fgloc.io.msgdefs.MSG_TEXT`) with Cyclone DDS' Python IDL (``make_idl_struct``),
primitives mapped as rosidl maps them to IDL (``byte`` -> octet, ``char`` -> uint8, ``T[]`` ->
unbounded sequence, ``T[N]`` -> array).  fgloc writes and reads the CDR bytes itself
(:mod:`fgloc.ros2.codec`): these classes give the topics their type, and let a test decode a
sample with Cyclone's own deserializer to check fgloc's bytes against it.
"""

from __future__ import annotations

import functools
from typing import Any

from fgloc.io.msgdefs import fields, short_name
from fgloc.ros2.names import dds_type


def _primitive(name: str) -> Any:
    import cyclonedds.idl.types as t

    return {
        "bool": bool, "byte": t.uint8, "char": t.uint8, "int8": t.int8, "uint8": t.uint8,
        "int16": t.int16, "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32, "int64": t.int64,
        "uint64": t.uint64, "float32": t.float32, "float64": t.float64, "string": str,
    }.get(name)


def _annotation(base: str, arr: str, classes: dict[str, Any]) -> Any:
    import cyclonedds.idl.types as t

    elem = _primitive(base)
    if elem is None:
        elem = classes[base]
    if not arr:
        return elem
    inner = arr[1:-1]
    if inner == "":
        return t.sequence[elem]  # type: ignore[misc]
    if inner.startswith("<="):
        return t.sequence[elem, int(inner[2:])]  # type: ignore[misc]
    return t.array[elem, int(inner)]  # type: ignore[misc]


@functools.cache
def idl_class(type_name: str) -> Any:
    """The Cyclone DDS IDL struct of ROS 2 type ``type_name`` (``pkg/msg/Type`` or ``pkg/Type``;
    one of :data:`fgloc.io.msgdefs.MSG_TEXT`), its DDS type name as rmw spells it."""
    from cyclonedds.idl import make_idl_struct

    defs = fields(type_name)
    classes: dict[str, Any] = {}

    def build(name: str) -> Any:
        if name in classes:
            return classes[name]
        if name != short_name(type_name) and name in _BUILT:
            classes[name] = _BUILT[name]
            return classes[name]
        for base, _, _ in defs[name]:
            if _primitive(base) is None:
                build(base)
        anns = {field: _annotation(base, arr, classes) for base, arr, field in defs[name]}
        cls = make_idl_struct(name.split("/")[-1], dds_type(name), anns)
        classes[name] = _BUILT[name] = cls
        return cls

    return build(short_name(type_name))


_BUILT: dict[str, Any] = {}  # one class per ROS type across idl_class calls (nested types shared)
