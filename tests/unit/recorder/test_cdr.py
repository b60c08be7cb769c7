"""recorder.icd.cdr encodes every thermcap message exactly as mcap_ros2's dynamic encoder does."""

from __future__ import annotations

import json
import math
import random
from typing import Any

import pytest
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd import rosmsg
from thermcap.recorder.icd.cdr import compile_encoder

MESSAGES = [rosmsg.SIDECAR, rosmsg.STATS, rosmsg.EVENT, rosmsg.RADAR_CUE, rosmsg.JSON_DOCUMENT]


def _same(name: str, text: str, fields: dict[str, Any]) -> bytes:
    theirs = serialize_dynamic(name, text)[name](fields)
    ours = compile_encoder(name, text)(fields)
    assert ours == theirs
    return ours


def _wild(rng: random.Random) -> Any:
    return rng.choice([None, 0, -1, 2**31 - 1, 3.5, -0.0, math.nan, math.inf, "", "ünï\u00e7ødé ✓", "x" * 301,
                       True, False, [1, 2, 3], {"a": 1}])


@pytest.mark.parametrize("message", MESSAGES, ids=lambda m: m.name)
def test_documents_of_every_shape_encode_as_mcap_ros2_does(message: rosmsg.RosMessage) -> None:
    rng = random.Random(7)
    docs: list[dict[str, Any]] = [{}]
    for frame in SimSource(width=64, height=48, frames=30, paced=False, seed=2).frames():
        docs.append(frame.sidecar)
        for _topic, msg in frame.messages:
            docs.append(msg)
    # odd values where the ICD has numbers: the field functions map them, the encoders must agree
    for _ in range(40):
        docs.append({"capture": {"frame_index": rng.randrange(0, 2**40), "timestamp": _wild(rng)},
                     "environment": {"ambient_temp_c": _wild(rng)},
                     "thermal_analysis": {"snr_db": _wild(rng), "source": _wild(rng)},
                     "targets": [{"target_id": _wild(rng), "bbox": [rng.randrange(-5, 700) for _ in range(4)],
                                  "centroid": [rng.uniform(-1, 1) for _ in range(rng.randrange(0, 3))],
                                  "confidence": _wild(rng)} for _ in range(rng.randrange(0, 4))],
                     "slew_to_cue": {"slew_to_cue_active": _wild(rng), "state": _wild(rng)},
                     "frames_captured": rng.randrange(0, 10**9), "kind": _wild(rng), "at_ns": rng.randrange(-1, 2**62)})
    for doc in docs:
        raw = json.dumps(doc, separators=(",", ":"), default=str)
        try:
            fields = {"json": raw, **message.fields(doc)}
        except (TypeError, ValueError):
            continue  # a value the field functions refuse is refused before either encoder
        data = _same(message.name, message.text, fields)
        decoded = generate_dynamic(message.name, message.text)[message.name](data)
        assert decoded.json == raw
        # what the recorder calls: the sidecar's hand layout, the plan for the others
        assert message.encode(doc, raw.encode()) == data


def test_annotations_encode_as_mcap_ros2_does() -> None:
    frames = list(SimSource(width=160, height=128, frames=40, paced=False, seed=3).frames())
    assert any(f.sidecar.get("targets") for f in frames), "the simulator drew no targets"
    for i, frame in enumerate(frames):
        doc = rosmsg.annotations_doc(1_700_000_000_123_456_789 + i, frame.sidecar.get("targets") or [])
        assert rosmsg.annotations_message(1_700_000_000_123_456_789 + i, frame.sidecar.get("targets") or []) == \
            _same(rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text, doc)
    _same(rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text, {})


def test_annotations_of_random_targets_encode_as_mcap_ros2_does() -> None:
    # the message's own layout: any number of targets, labels of every length (each text's
    # padding depends on the label before it), unicode, stamps at the edges of a second
    rng = random.Random(11)
    for k in range(200):
        targets = []
        for _ in range(rng.randrange(0, 7)):
            x, y = rng.randrange(0, 600), rng.randrange(0, 500)
            targets.append({"target_id": rng.choice(["T", "TGT0", "ünï", "x" * rng.randrange(0, 12), 7, None]),
                            "bbox": [x, y, x + rng.randrange(0, 40), y + rng.randrange(0, 40)],
                            "max_temp_c": rng.choice([None, 41.5, -12.25, 1e6, rng.uniform(-40, 500)])})
        if rng.random() < 0.1:
            targets.append({"target_id": "no box", "bbox": [1, 2]})  # drawn by neither
        stamp = rng.choice([0, 999_999_999, 1_000_000_000, 1_700_000_000_000_000_000 + k * 16_666_667])
        assert rosmsg.annotations_message(stamp, targets) == \
            _same(rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text, rosmsg.annotations_doc(stamp, targets))


def test_alignment_after_odd_sized_fields() -> None:
    text = "uint8 a\nfloat64[] b\nstring s\nint16 c\nbool[] d\nuint64 e\nstring[] f\n"
    for b in ([], [1.5], [1.0, 2.0, 3.0]):
        for s in ("", "a", "abc", "abcd"):
            _same("t/msg/Odd", text, {"a": 3, "b": b, "s": s, "c": -2, "d": [True, False, True], "e": 2**63,
                                      "f": ["", "xy", "z"]})


def test_fixed_size_runs_start_at_every_offset_and_coerce_what_struct_refuses() -> None:
    # a run of fixed-size fields (nested ones included) after a string of each length: every
    # one of the eight layouts; values struct will not pack as given take the coerced path
    text = ("string s\nuint8 a\nfloat64 x\nP p\nint32 n\nint16 h\nstring t\nbool b\nfloat32 g\n"
            "================================================================================\n"
            "MSG: t/P\nfloat32 u\nuint64 v\n")
    for s in ("", "a", "ab", "abc", "abcd", "abcde", "abcdef", "abcdefg"):
        _same("t/msg/Run", text, {"s": s, "a": 1, "x": 2.5, "p": {"u": 1.25, "v": 9}, "n": -3, "h": 4,
                                          "t": s, "b": True, "g": 0.5})
        _same("t/msg/Run", text, {"s": s, "a": True, "x": "1.5", "p": {"u": 3, "v": 2.0}, "n": 3.7, "h": None,
                                          "t": "", "b": 2, "g": "2"})
        _same("t/msg/Run", text, {"s": s, "p": None})


def test_what_the_plan_does_not_cover_falls_back_to_mcap_ros2() -> None:
    text = "float64[3] fixed\nint32[<=4] bounded\nstring<=5 short\n"
    fields = {"fixed": [1.0, 2.0, 3.0], "bounded": [1, 2], "short": "abcdefgh"}
    assert compile_encoder("t/msg/Fixed", text)(fields) == serialize_dynamic("t/msg/Fixed", text)["t/msg/Fixed"](fields)


def test_without_mcap_ros2_s_parser_helpers_its_own_encoder_is_used(monkeypatch: pytest.MonkeyPatch) -> None:
    """The helpers compile_encoder parses with are private to mcap_ros2: a release without them,
    or with a parser of another shape, must leave recording working on mcap_ros2's encoder."""
    import thermcap.recorder.icd.cdr as cdr

    name, text = rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text
    doc = rosmsg.annotations_doc(5, [{"target_id": "T1", "bbox": [1, 2, 30, 40]}])
    theirs = serialize_dynamic(name, text)[name](doc)

    def other_shape(*_args: Any) -> None:
        raise AttributeError("'MessageSpecification' object has no attribute 'fields'")

    for parser in (None, (object(), other_shape)):
        monkeypatch.setattr(cdr, "_parser", lambda parser=parser: parser)
        assert compile_encoder(name, text)(doc) == theirs
