"""ROS 2 type hashes (REP 2011, ``RIHS01_<sha256>``) of the messages fgloc exchanges.

ROS 2 Iron and later describe every topic's type by a hash of its *type description*: the type's
fields and, sorted by name, those of every type it reaches.  rmw_cyclonedds_cpp puts it in each
reader's and writer's DDS USER_DATA as ``typehash=RIHS01_<64 hex digits>;``
(``rmw_dds_common::encode_type_hash_for_user_data_qos``) and ``ros2 topic info -v`` shows it.

The hash here is computed as rosidl_generator_type_description computes it at build time
(``calculate_type_hash``): the description as JSON, every field
``{"name", "type": {"type_id", "capacity", "string_capacity", "nested_type_name"}}`` (the
default values left out), ``json.dumps`` with ``", "`` / ``": "`` separators and no sorting,
then SHA-256.  Field type ids are type_description_interfaces/msg/FieldType's: the element's id,
plus 48 for a fixed array, 96 for a bounded sequence, 144 for an unbounded one.  A ``.msg`` type
reaches the description through its IDL form (rosidl_adapter): ``char`` is ``uint8``, ``byte``
``octet``; constants are no fields.

The field lists come from :func:`fgloc.io.msgdefs.fields` (the one copy of each message) and,
for the types of ROS 2's own discovery topic, from :data:`EXTRA_FIELDS`.
"""

from __future__ import annotations

import functools
import hashlib
import json
from typing import Any

from fgloc.io.msgdefs import MSG_TEXT, fields, short_name

PREFIX = "RIHS01_"

#: type_description_interfaces/msg/FieldType ids of the element types (the .msg primitive names)
ELEMENT_IDS = {
    "nested": 1, "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8,
    "uint64": 9, "float32": 10, "float64": 11, "char": 3, "bool": 15, "byte": 16, "string": 17,
    "wstring": 18, "bounded_string": 21, "bounded_wstring": 22,
}
ARRAY_OFFSET, BOUNDED_SEQUENCE_OFFSET, UNBOUNDED_SEQUENCE_OFFSET = 48, 96, 144

#: rmw_dds_common's messages (ROS 2 Iron and later: a 16-byte Gid), ``{pkg/Type: [(type, suffix, name)]}``
EXTRA_FIELDS: dict[str, list[tuple[str, str, str]]] = {
    "rmw_dds_common/Gid": [("char", "[16]", "data")],
    "rmw_dds_common/NodeEntitiesInfo": [
        ("string<=256", "", "node_namespace"), ("string<=256", "", "node_name"),
        ("rmw_dds_common/Gid", "[]", "reader_gid_seq"), ("rmw_dds_common/Gid", "[]", "writer_gid_seq"),
    ],
    "rmw_dds_common/ParticipantEntitiesInfo": [
        ("rmw_dds_common/Gid", "", "gid"),
        ("rmw_dds_common/NodeEntitiesInfo", "[]", "node_entities_info_seq"),
    ],
}


def full_name(type_name: str) -> str:
    """``sensor_msgs/LaserScan`` or ``sensor_msgs/msg/LaserScan`` -> ``sensor_msgs/msg/LaserScan``."""
    pkg, name = short_name(type_name).split("/")
    return f"{pkg}/msg/{name}"


def _all_fields(type_name: str) -> dict[str, list[tuple[str, str, str]]]:
    name = short_name(type_name)
    if name in MSG_TEXT:
        return fields(name)
    if name not in EXTRA_FIELDS:
        raise KeyError(f"{type_name}: fgloc has no definition of this type")
    out: dict[str, list[tuple[str, str, str]]] = {}
    todo = [name]
    while todo:
        t = todo.pop()
        if t in out:
            continue
        out[t] = EXTRA_FIELDS[t]
        todo += [base for base, _, _ in out[t] if base in EXTRA_FIELDS]
    return out


def _field_type(base: str, suffix: str) -> dict[str, Any]:
    string_capacity = 0
    nested = ""
    if base.startswith(("string<=", "wstring<=")):
        kind, bound = base.split("<=")
        element = ELEMENT_IDS["bounded_" + kind]
        string_capacity = int(bound)
    elif base in ELEMENT_IDS and base not in ("nested", "bounded_string", "bounded_wstring"):
        element = ELEMENT_IDS[base]
    else:
        element = ELEMENT_IDS["nested"]
        nested = full_name(base)
    capacity = 0
    if suffix == "[]":
        element += UNBOUNDED_SEQUENCE_OFFSET
    elif suffix.startswith("[<="):
        element += BOUNDED_SEQUENCE_OFFSET
        capacity = int(suffix[3:-1])
    elif suffix:
        element += ARRAY_OFFSET
        capacity = int(suffix[1:-1])
    return {"type_id": element, "capacity": capacity, "string_capacity": string_capacity,
            "nested_type_name": nested}


def type_description(type_name: str) -> dict[str, Any]:
    """The hashed form of ``type_name``'s TypeDescription: ``{"type_description": {...},
    "referenced_type_descriptions": [...]}`` (sorted by type name; default values left out)."""
    defs = _all_fields(type_name)

    def individual(name: str) -> dict[str, Any]:
        return {"type_name": full_name(name),
                "fields": [{"name": f, "type": _field_type(b, a)} for b, a, f in defs[name]]}

    root = short_name(type_name)
    refs = sorted((n for n in defs if n != root), key=full_name)
    return {"type_description": individual(root),
            "referenced_type_descriptions": [individual(n) for n in refs]}


@functools.cache
def type_hash(type_name: str) -> str:
    """``RIHS01_<sha256 hex>`` of ROS 2 type ``type_name`` (any spelling)."""
    text = json.dumps(type_description(type_name), skipkeys=False, ensure_ascii=True, check_circular=True,
                      allow_nan=False, indent=None, separators=(", ", ": "), sort_keys=False)
    return PREFIX + hashlib.sha256(text.encode("utf-8")).hexdigest()


def user_data(type_name: str) -> bytes:
    """The endpoint USER_DATA rmw_cyclonedds_cpp writes for a topic of ``type_name``."""
    return f"typehash={type_hash(type_name)};".encode()
