"""``thermcap bench cdr``: the two messages laid out by hand for every frame (the sidecar, the
targets' marks) against the libraries they stand in for, mcap_ros2's dynamic encoder and
rosbags' ``serialize_cdr``, on the simulator's documents, in one run. rosbags is the anchor
(``x rosbags`` = its time over ours); the bytes of all three are checked equal first, so a fast
wrong encoder cannot win. The low-rate messages (stats, events) are encoded by mcap_ros2 in the
recorder and appear here only so the gap a hand layout buys is seen beside what it costs.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import numpy as np

from thermcap.benches.harness import best_of
from thermcap.recorder.icd import rosmsg
from thermcap.recorder.icd.cdr import library_encoder

__all__ = ["bench_cdr", "print_table"]

_SEP = "=" * 80
#: rosbags wants numpy arrays for sequences of numbers
_DTYPES = {"bool": np.bool_, "int8": np.int8, "uint8": np.uint8, "byte": np.uint8, "char": np.uint8,
           "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
           "uint64": np.uint64, "float32": np.float32, "float64": np.float64}


def _rosbags_encoder(name: str, text: str) -> Callable[[dict[str, Any]], bytes] | None:
    """rosbags' encoder for a ros2msg definition as MCAP embeds it, taking the same dict the
    recorder's encoders take; None without rosbags (the ``ros2`` extra)."""
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError:
        return None
    store = get_typestore(Stores.EMPTY)
    blocks = text.split(_SEP)
    types = dict(get_types_from_msg(blocks[0], name))
    for block in blocks[1:]:
        header, _, body = block.strip("\n").partition("\n")
        pkg, _, short = header.removeprefix("MSG: ").strip().rpartition("/")
        types.update(get_types_from_msg(body, f"{pkg}/msg/{short}"))
    if "builtin_interfaces/msg/Time" not in types:
        types.update(get_types_from_msg("int32 sec\nuint32 nanosec", "builtin_interfaces/msg/Time"))
    store.register(types)

    def build(typename: str, doc: dict[str, Any]) -> Any:
        _consts, fields = store.fielddefs[typename]
        values = {}
        for fname, (kind, desc) in fields:
            values[fname] = value(kind, desc, doc.get(fname))
        return store.types[typename](**values)

    def value(kind: int, desc: Any, v: Any) -> Any:
        if kind == 1:  # a primitive or a string
            base = desc[0]
            if base == "string":
                return "" if v is None else str(v)
            return _DTYPES[base](0 if v is None else v).item()
        if kind == 2:  # a message
            return build(desc, v or {})
        (inner_kind, inner), _size = desc
        items = v or []
        if inner_kind == 1 and inner[0] != "string":
            return np.array(items, dtype=_DTYPES[inner[0]])
        return [value(inner_kind, inner, i) for i in items]

    return lambda doc: store.serialize_cdr(build(name, doc), name).tobytes()


def _documents(n_frames: int) -> tuple[list[dict[str, Any]], list[tuple[int, list[dict[str, Any]]]]]:
    from thermcap.recorder.capture.sources.sim import SimSource

    frames = list(SimSource(width=320, height=256, frames=n_frames, paced=False, seed=5).frames())
    sidecars = [f.sidecar for f in frames]
    marks = [(1_700_000_000_000_000_000 + i * 16_666_667, f.sidecar.get("targets") or []) for i, f in enumerate(frames)]
    return sidecars, marks


def bench_cdr(n_frames: int = 120, repeat: int = 20) -> dict[str, Any]:
    sidecars, marks = _documents(n_frames)
    rows = []

    def row(message: str, hand: Callable[[int], bytes] | None, fields: Callable[[int], dict[str, Any]],
            name: str, text: str) -> None:
        lib = library_encoder(name, text)
        rb = _rosbags_encoder(name, text)
        for i in range(n_frames):  # the same bytes from every encoder, or no figure
            ref = lib(fields(i))
            assert hand is None or hand(i) == ref, f"{message} {i}: the hand layout differs from mcap_ros2"
            assert rb is None or rb(fields(i)) == ref, f"{message} {i}: rosbags differs from mcap_ros2"
        # each from the recorded document, as the recorder pays it (the fields made from it included)
        out: dict[str, Any] = {"message": message, "frames": n_frames}
        def us(encode: Callable[[int], bytes]) -> float:
            return round(best_of(lambda: [encode(i) for i in range(n_frames)], repeat) * 1e6 / n_frames, 2)

        if hand is not None:
            out["hand_us"] = us(hand)
        out["mcap_ros2_us"] = us(lambda i: lib(fields(i)))
        if rb is not None:
            out["rosbags_us"] = us(lambda i: rb(fields(i)))
            best = out.get("hand_us", out["mcap_ros2_us"])
            out["x_rosbags"] = round(out["rosbags_us"] / best, 2)
        rows.append(out)

    raws = [json.dumps(s, separators=(",", ":")).encode() for s in sidecars]
    side = rosmsg.SIDECAR
    row("sidecar (every frame)", lambda i: side.encode(sidecars[i], raws[i]),
        lambda i: {"json": raws[i].decode(), **side.fields(sidecars[i])}, side.name, side.text)
    row("target marks (every frame)", lambda i: rosmsg.annotations_message(*marks[i]),
        lambda i: rosmsg.annotations_doc(*marks[i]), rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text)
    stats = {"frames_captured": 600, "frames_written": 598, "queue_depth": 2, "queue_capacity": 64,
             "timing": {"achieved_fps": 59.99}, "write_latency_ms": {"interval": {"p50": 0.4, "p99": 1.9}}}
    stats_raw = json.dumps(stats)
    row("recorder stats (once a second)", None, lambda i: {"json": stats_raw, **rosmsg.STATS.fields(stats)},
        rosmsg.STATS.name, rosmsg.STATS.text)
    return {"rows": rows, "anchor": "rosbags serialize_cdr", "rosbags": rows[0].get("rosbags_us") is not None}


def print_table(res: dict[str, Any]) -> str:
    lines = [f"{'message':32} {'by hand':>9} {'mcap_ros2':>10} {'rosbags':>9} {'x rosbags':>10}  (us a message)"]
    for r in res["rows"]:
        lines.append(f"{r['message']:32} {r.get('hand_us', '-')!s:>9} {r['mcap_ros2_us']!s:>10} "
                     f"{r.get('rosbags_us', '-')!s:>9} {r.get('x_rosbags', '-')!s:>10}")
    if not res["rosbags"]:
        lines.append("rosbags is not installed (pip install 'thermcap[ros2]'): no anchor in this run")
    return "\n".join(lines)
