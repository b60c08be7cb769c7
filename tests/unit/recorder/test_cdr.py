"""Every thermcap message is encoded exactly as mcap_ros2's dynamic encoder does: the two laid
out by hand for every frame (the sidecar, the targets' marks) byte for byte against it, and the
low-rate ones by it."""

from __future__ import annotations

import json
import math
import random
from typing import Any

import pytest
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd import rosmsg

MESSAGES = [rosmsg.SIDECAR, rosmsg.STATS, rosmsg.EVENT, rosmsg.RADAR_CUE, rosmsg.JSON_DOCUMENT]


def _theirs(name: str, text: str, fields: dict[str, Any]) -> bytes:
    return serialize_dynamic(name, text)[name](fields)


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
        data = _theirs(message.name, message.text, fields)
        decoded = generate_dynamic(message.name, message.text)[message.name](data)
        assert decoded.json == raw
        # what the recorder calls: the sidecar's hand layout, the library for the others
        assert message.encode(doc, raw.encode()) == data


def test_annotations_encode_as_mcap_ros2_does() -> None:
    frames = list(SimSource(width=160, height=128, frames=40, paced=False, seed=3).frames())
    assert any(f.sidecar.get("targets") for f in frames), "the simulator drew no targets"
    for i, frame in enumerate(frames):
        doc = rosmsg.annotations_doc(1_700_000_000_123_456_789 + i, frame.sidecar.get("targets") or [])
        assert rosmsg.annotations_message(1_700_000_000_123_456_789 + i, frame.sidecar.get("targets") or []) == \
            _theirs(rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text, doc)


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
            _theirs(rosmsg.ANNOTATIONS.name, rosmsg.ANNOTATIONS.text, rosmsg.annotations_doc(stamp, targets))
