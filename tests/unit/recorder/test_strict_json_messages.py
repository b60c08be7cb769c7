"""Issue 36: a source's own messages were written with Python's default ``allow_nan=True``: a NaN
in a radar cue was kept as the token ``NaN``, which strict JSON readers refuse. They are standard
JSON now, the non-finite value named beside it."""

from __future__ import annotations

import json

from mcap.reader import make_reader

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd.rosmsg import json_payload


class _NanCues(SimSource):
    def frames(self):
        for f in super().frames():
            f.messages = [("/radar/cue", {"cue_id": f.index, "azimuth_deg": float("nan"),
                                          "track": [1.0, float("inf")]})]
            yield f


def test_a_source_message_with_nan_is_standard_json(tmp_path):
    Recorder(_NanCues(width=32, height=24, frames=5, paced=False, cue_period_s=0), tmp_path, session_id="n",
             analysis=False).run()
    docs = []
    for seg in sorted((tmp_path / "sessions" / "n").glob("*.mcap")):
        with open(seg, "rb") as f:
            for _, ch, msg in make_reader(f).iter_messages(topics=["/radar/cue"]):
                docs.append(json.loads(json_payload(ch.message_encoding, msg.data),
                                       parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c))))
    assert len(docs) == 5
    assert docs[0]["azimuth_deg"] is None and docs[0]["_non_finite"] == {"azimuth_deg": "NaN", "track[1]": "Infinity"}
