"""CDR (little-endian, XCDR1) encoders compiled once from a ros2msg definition.

Why: every frame carries two messages built from documents, its sidecar and its targets' marks.
mcap_ros2's dynamic encoder looks every field up and coerces it generically; on the recorder's
writer thread that was 0.12 ms a frame, a twentieth of the recorder's CPU, enough to put it
above foxglove-sdk's Rust writer. Here each message is turned once into a flat plan of struct
formats, and encoding is a walk over that plan. The bytes are mcap_ros2's own (the tests
compare every thermcap message with it), and mcap_ros2 still parses the definitions; a
definition using what the plan does not cover (fixed-size or bounded arrays, wide strings)
gets mcap_ros2's encoder instead.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

__all__ = ["compile_encoder", "pad", "phase_layouts", "write_string"]

#: ros2msg primitive -> (struct code, size); bool and byte are written as uint8, as ROS 2 does
_PRIMITIVES: dict[str, tuple[str, int]] = {
    "bool": ("B", 1), "byte": ("B", 1), "char": ("B", 1), "int8": ("b", 1), "uint8": ("B", 1),
    "int16": ("h", 2), "uint16": ("H", 2), "int32": ("i", 4), "uint32": ("I", 4),
    "int64": ("q", 8), "uint64": ("Q", 8), "float32": ("f", 4), "float64": ("d", 8),
}
_INTS = {"byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}
_U32 = struct.Struct("<I")

Writer = Callable[[bytearray, Any], None]


class _Unsupported(Exception):
    pass


def pad(out: bytearray, size: int) -> None:
    """Public, with ``write_string``, so a message laid out by hand (the marks, the sidecar) pads as the plan does."""
    # the four-byte encapsulation header does not count towards alignment
    gap = -(len(out) - 4) % size
    if gap:
        out += b"\0" * gap


#: a string's length, after the padding that 4-aligns it, by the offset modulo 4
_LENGTH_AT = [struct.Struct("<" + "x" * (-phase % 4) + "I") for phase in range(4)]


def write_string(out: bytearray, value: Any) -> None:
    data = (value if value.__class__ is str else "" if value is None else str(value)).encode("utf-8")
    out += _LENGTH_AT[(len(out) - 4) % 4].pack(len(data) + 1)  # the header's four bytes do not count
    out += data
    out.append(0)


def phase_layouts(codes: list[str]) -> list[struct.Struct]:
    """A run of fixed-size fields (struct codes, one field each) as one struct per offset the run
    can start at, modulo 8: CDR pads each field to its own size counted from the stream's start,
    so the padding inside the run depends on where it starts. ``layouts[(len(out) - 4) % 8]``."""
    layouts = []
    for phase in range(8):
        fmt, at = "<", phase
        for code in codes:
            size = struct.calcsize(code)
            gap = -at % size
            fmt += "x" * gap + code
            at += gap + size
        layouts.append(struct.Struct(fmt))
    return layouts


def _coerce(kind: str) -> Callable[[Any], Any]:
    if kind == "bool":
        return lambda v: 1 if v else 0
    if kind in _INTS:
        return lambda v: 0 if v is None else int(v)
    return lambda v: 0.0 if v is None else float(v)


def _field_writer(ftype: Any, msgdefs: dict[str, Any]) -> Writer:
    kind = ftype.type
    if ftype.is_array and (ftype.is_fixed_size_array() or ftype.is_upper_bound):
        raise _Unsupported(f"{kind}[{ftype.array_size}]")
    if getattr(ftype, "string_upper_bound", None):
        raise _Unsupported(f"{kind}<={ftype.string_upper_bound}")
    if ftype.is_primitive_type():
        if kind == "string":
            if not ftype.is_array:
                return write_string

            def strings(out: bytearray, values: Any) -> None:
                values = values or []
                pad(out, 4)
                out += _U32.pack(len(values))
                for v in values:
                    write_string(out, v)
            return strings
        if kind not in _PRIMITIVES:
            raise _Unsupported(kind)
        assert ftype.is_array, "a single number is packed with its neighbours by _run_writer"
        code, size = _PRIMITIVES[kind]
        coerce = _coerce(kind)

        def scalars(out: bytearray, values: Any) -> None:
            values = list(values) if values is not None else []
            pad(out, 4)
            out += _U32.pack(len(values))
            if values:
                if size > 1:
                    pad(out, size)
                out += struct.pack(f"<{len(values)}{code}", *map(coerce, values))
        return scalars
    nested = msgdefs.get(f"{ftype.pkg_name}/{kind}")
    if nested is None:
        raise _Unsupported(f"{ftype.pkg_name}/{kind}")
    body = _struct_writer(nested, msgdefs)
    if not ftype.is_array:
        return lambda out, value: body(out, value or {})

    def structs(out: bytearray, values: Any) -> None:
        values = values or []
        pad(out, 4)
        out += _U32.pack(len(values))
        for v in values:
            body(out, v or {})
    return structs


def _flat_values(ftype: Any, msgdefs: dict[str, Any]) -> list[tuple[tuple[str, ...], str]] | None:
    """The (path, primitive) leaves of a field that is one fixed-size record: a numeric scalar,
    or a struct (not an array) of such fields. None for anything else (strings, arrays)."""
    if ftype.is_array or getattr(ftype, "string_upper_bound", None):
        return None
    if ftype.is_primitive_type():
        return [((), ftype.type)] if ftype.type in _PRIMITIVES else None
    nested = msgdefs.get(f"{ftype.pkg_name}/{ftype.type}")
    if nested is None or not nested.fields:
        return None
    leaves: list[tuple[tuple[str, ...], str]] = []
    for f in nested.fields:
        inner = _flat_values(f.type, msgdefs)
        if inner is None:
            return None
        leaves += [((f.name, *path), kind) for path, kind in inner]
    return leaves


def _run_writer(leaves: list[tuple[tuple[str, ...], str]]) -> Writer:
    """One writer for consecutive fixed-size fields (a Point2, a Color, a Time, the scalars
    between two strings): a single struct pack instead of a call per field. CDR pads each
    field to its own size counted from the stream's start, so the padding depends on where the
    run starts modulo 8; the eight possible layouts are compiled ahead."""
    layouts = phase_layouts([_PRIMITIVES[kind][0] for _, kind in leaves])
    coerces = [_coerce(kind) for _, kind in leaves]
    exact = not any(kind == "bool" for _, kind in leaves)  # a bool is 0/1 whatever truthy value it had
    tops = [path[0] for path, _ in leaves]
    nested = any(len(path) > 1 for path, _ in leaves)

    def values(doc: Any) -> list[Any]:
        if not nested:
            get = doc.get
            return [get(name) for name in tops]
        out = []
        for path, _ in leaves:
            v = doc
            for key in path:
                v = (v or {}).get(key)
            out.append(v)
        return out

    def write(out: bytearray, doc: Any) -> None:
        vals = values(doc)
        layout = layouts[(len(out) - 4) % 8]
        if exact and None not in vals:
            try:
                out += layout.pack(*vals)
                return
            except (struct.error, TypeError, OverflowError):
                pass  # a value struct will not take as it is (a "1.5", a float for an int): coerce it
        out += layout.pack(*[c(v) for c, v in zip(coerces, vals, strict=True)])
    return write


def _struct_writer(msgdef: Any, msgdefs: dict[str, Any]) -> Writer:
    if not msgdef.fields:  # ROS 2 gives an empty message one uint8 member
        return lambda out, doc: out.append(0)
    steps: list[Writer] = []
    run: list[tuple[tuple[str, ...], str]] = []
    for f in msgdef.fields:
        leaves = _flat_values(f.type, msgdefs)
        if leaves is not None:
            run += [((f.name, *path), kind) for path, kind in leaves]
            continue
        if run:
            steps.append(_run_writer(run))
            run = []
        steps.append(_field(f.name, _field_writer(f.type, msgdefs)))
    if run:
        steps.append(_run_writer(run))
    if len(steps) == 1:
        return steps[0]

    def write(out: bytearray, doc: Any) -> None:
        for step in steps:
            step(out, doc)
    return write


def _field(name: str, w: Writer) -> Writer:
    return lambda out, doc: w(out, doc.get(name))


def _parser() -> tuple[Any, Callable[..., None]] | None:
    """mcap_ros2's definition parser (its Time definition, its walk over a concatenated
    definition), or None where a release no longer has them: they are not its public API."""
    try:
        from mcap_ros2._dynamic import TimeDefinition, _for_each_msgdef
    except ImportError:
        return None
    return TimeDefinition, _for_each_msgdef


def compile_encoder(schema_name: str, schema_text: str) -> Callable[[dict[str, Any]], bytes]:
    """``encode(doc) -> bytes`` for the message ``schema_name`` of a concatenated ros2msg
    definition, as mcap_ros2's ``serialize_dynamic`` would encode ``doc`` (a dict; missing
    fields take their zero value)."""
    from mcap_ros2._dynamic import serialize_dynamic

    parser = _parser()
    if parser is None:
        return serialize_dynamic(schema_name, schema_text)[schema_name]
    time_definition, for_each_msgdef = parser
    msgdefs: dict[str, Any] = {"builtin_interfaces/Time": time_definition,
                               "builtin_interfaces/Duration": time_definition}

    def keep(full: str, short: str, msgdef: Any) -> None:
        msgdefs[full] = msgdefs[short] = msgdef

    try:
        for_each_msgdef(schema_name, schema_text, keep)
        body = _struct_writer(msgdefs[schema_name], msgdefs)
    except (_Unsupported, AttributeError, KeyError):  # AttributeError: a parser of another shape
        return serialize_dynamic(schema_name, schema_text)[schema_name]

    def encode(doc: dict[str, Any]) -> bytes:
        out = bytearray(b"\x00\x01\x00\x00")  # CDR_LE, no options
        body(out, doc)
        return bytes(out)
    return encode
