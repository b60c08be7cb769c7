"""The hot-spot detector against known targets, tracking, events, and its place in the recorder."""

from __future__ import annotations

import json

import numpy as np
import pytest

from thermcap.benches.analysis import score
from thermcap.recorder.analysis.detector import EventBuilder, HotSpotDetector, iou
from thermcap.recorder.analysis.offline import analyze_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource, SimTarget
from thermcap.recorder.radiometry import LinearModel

MODEL = LinearModel()


def _flat(h=256, w=320, temp=20.0, seed=0):
    rng = np.random.default_rng(seed)
    return MODEL.from_celsius(temp + rng.normal(0, 0.05, (h, w)))


def test_flat_noisy_scene_has_no_detection():
    det = HotSpotDetector(MODEL)
    for seed in range(5):
        dets, analysis = det.detect(_flat(seed=seed))
        assert dets == []
        assert analysis["thermal_contrast_grade"] == 0.0
        assert analysis["max_target_temp_c"] is None


def test_hand_placed_target_found_with_exact_box_and_icd_metrics():
    temps = np.full((128, 160), 20.0)
    temps[40:46, 70:78] = 35.0
    dets, analysis = HotSpotDetector(MODEL).detect(MODEL.from_celsius(temps))
    (d,) = dets
    assert d.bbox == [70, 40, 77, 45]
    assert d.centroid == pytest.approx([73.5, 42.5], abs=0.01)
    assert d.max_temp_c == pytest.approx(35.0, abs=0.04)
    assert analysis["delta_t_deg_c"] == pytest.approx(15.0, abs=0.08)
    assert analysis["thermal_contrast_grade"] == 1.0
    assert analysis["source"] == "detector"


def test_below_the_5k_threshold_is_not_a_target():
    temps = np.full((128, 160), 20.0)
    temps[40:46, 70:78] = 24.5
    assert HotSpotDetector(MODEL).detect(MODEL.from_celsius(temps))[0] == []


def test_simulated_targets_found_within_one_pixel():
    src = SimSource(frames=20, paced=False, seed=3, start_time_ns=0)
    det = HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map)
    for f in src.frames():
        truth = next(m for t, m in f.messages if t == "/sim/ground_truth")["targets"]
        dets, _ = det.detect(f.pixels)
        tp, fp, fn, _matched = score([t["bbox"] for t in truth], [d.bbox for d in dets])
        assert (tp, fp, fn) == (3, 0, 0)
        for t in truth:
            d = max(dets, key=lambda d: iou(d.bbox, t["bbox"]))
            assert abs(d.centroid[0] - t["centroid"][0]) <= 1
            assert abs(d.centroid[1] - t["centroid"][1]) <= 1


def test_bad_pixels_are_not_targets():
    src = SimSource(frames=2, paced=False, seed=1, targets=(), start_time_ns=0)
    frames = list(src.frames())
    assert (frames[0].pixels[src.bad_pixel_map] == 16383).any()
    assert HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map).detect(frames[0].pixels)[0] == []


def test_tracking_ids_are_stable_across_frames():
    src = SimSource(frames=60, paced=False, seed=2, start_time_ns=0)
    det = HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map)
    ids = [tuple(sorted(d.target_id for d in det.detect(f.pixels)[0])) for f in src.frames()]
    assert len(set(ids)) == 1
    assert len(ids[0]) == 3


def test_a_target_fades_through_crossover():
    tgt = (SimTarget("X", "test", 0.0, (10, 10), (0.5, 0.7), (0.0, 0.0), "ground", delta_k=20.0),)
    src = SimSource(frames=180, fps=60, paced=False, seed=4, targets=tgt, crossover=True, start_time_ns=0)
    det = HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map)
    out = [det.detect(f.pixels) for f in src.frames()]
    counts = [len(d) for d, _ in out]
    grades = [a["thermal_contrast_grade"] for _, a in out]
    assert counts[0] == 1
    assert counts[-1] == 1
    assert counts[90] == 0
    assert grades[0] == 1.0
    assert grades[90] < 0.3


def test_event_builder_finds_crossover_and_slew_spans():
    eb = EventBuilder(min_crossover_s=0.5)
    for i in range(120):
        grade = 0.1 if 30 <= i < 90 else 1.0
        state = "slew" if 10 <= i < 20 else ("search" if 20 <= i < 25 else ("lock" if 25 <= i < 40 else "idle"))
        eb.add(i * 16_666_667, {"thermal_analysis": {"thermal_contrast_grade": grade, "delta_t_deg_c": 3.0,
                                                     "source": "detector"},
                                "slew_to_cue": {"state": state,
                                                "slew_to_cue_active": state in ("slew", "search", "lock")}})
    events = eb.finish()
    kinds = [(e["kind"], round(e["start_ns"] / 16_666_667), round(e["end_ns"] / 16_666_667)) for e in events]
    assert kinds == [("slew_to_cue", 10, 25), ("thermal_crossover", 30, 89)]


def test_frames_with_nothing_to_grade_make_no_crossover():
    """A frame with no target has the placeholder grade 0.0 and no delta T: not a crossover."""
    eb = EventBuilder(min_crossover_s=0.5)
    for i in range(120):
        eb.add(i * 16_666_667, {"thermal_analysis": {"thermal_contrast_grade": 0.0, "delta_t_deg_c": None,
                                                     "source": "detector"}})
    assert eb.finish() == []


def test_recorder_fills_sidecars_from_the_detector_and_writes_events(tmp_path):
    from thermcap.recorder.storage.reader import iter_session_frames

    # Paced at 60 fps, as a camera: the detector keeps up and analyses every frame.
    res = Recorder(SimSource(width=320, height=256, frames=90, paced=True, seed=5, first_cue_s=0.2,
                             start_time_ns=0), tmp_path, session_id="a").run()
    # A loaded machine makes the detector skip frames rather than hold capture back (11 of 90 with
    # a soak and CI beside it); each is counted, never hidden, and most are analysed.
    assert res.error is None
    assert res.frames_dropped == 0
    assert res.analysis_skipped <= len(range(90)) // 2
    assert res.ok == (res.analysis_skipped == 0)  # a skipped frame is reported, never hidden
    frames = list(iter_session_frames(tmp_path / "sessions" / "a"))
    side = [f.sidecar_dict() for f in frames]
    analysed = [s for s in side if s["thermal_analysis"]["source"] == "detector"]
    assert len(analysed) == len(side) - res.analysis_skipped
    assert all(len(s["targets"]) == 3 and s["targets"][0]["target_id"].startswith("HS") for s in analysed)
    events = json.loads((tmp_path / "sessions" / "a" / "events.json").read_text())["events"]
    assert [e["kind"] for e in events] == ["slew_to_cue"]


def test_analysis_falling_behind_skips_and_says_so(tmp_path):
    from thermcap.benches.record import MemorySource
    from thermcap.recorder.storage.reader import iter_session_frames

    sim = SimSource(width=320, height=256, frames=30, paced=False, seed=6, start_time_ns=0)
    frames = list(sim.frames())
    rec = Recorder(MemorySource(sim, frames, 300), tmp_path, session_id="b", queue_frames=300, analysis_queue=1,
                   analysis_max_fps=10_000, analysis_wait_s=0.0)
    res = rec.run()
    assert res.frames_written == 300
    assert res.frames_dropped == 0  # capture never waited for analysis
    assert res.analysis_skipped > 0
    side = [f.sidecar_dict()["thermal_analysis"]["source"] for f in iter_session_frames(tmp_path / "sessions" / "b")]
    assert side.count("skipped") == res.analysis_skipped


def test_analyze_is_idempotent_and_matches_the_recorder(tmp_path):
    Recorder(SimSource(width=320, height=256, frames=60, paced=False, seed=7, start_time_ns=0), tmp_path,
             session_id="c", analysis=False).run()
    d = tmp_path / "sessions" / "c"
    first = analyze_session(d)
    body = (d / "analysis.jsonl").read_bytes()
    events = (d / "events.json").read_bytes()
    analyze_session(d)
    assert (d / "analysis.jsonl").read_bytes() == body
    assert (d / "events.json").read_bytes() == events
    rows = [json.loads(line) for line in body.splitlines()]
    assert len(rows) == 60 == first["frames"]
    assert all(r["thermal_analysis"]["source"] == "detector" and len(r["targets"]) == 3 for r in rows)


@pytest.mark.parametrize("shape", [(128, 160), (7, 9), (1, 1), (40, 3)])
@pytest.mark.parametrize("k", [1, 2, 5, 13, 14])
def test_the_sliding_extremes_are_scipys_filters(shape, k):
    from scipy import ndimage

    from thermcap.recorder.analysis.detector import sliding_extreme

    x = np.random.default_rng(k).standard_normal(shape).astype(np.float32)
    assert np.array_equal(sliding_extreme(x, k, np.minimum), ndimage.minimum_filter(x, size=k, mode="nearest"))
    assert np.array_equal(sliding_extreme(x, k, np.maximum), ndimage.maximum_filter(x, size=k, mode="nearest"))


@pytest.mark.parametrize("n", [1, 2, 3, 10, 101])
def test_the_ring_median_is_numpys(n):
    from thermcap.recorder.analysis.detector import _median

    x = np.random.default_rng(n).standard_normal(n).astype(np.float32) * 30
    assert _median(x) == float(np.median(x))


def test_the_detectors_worst_case_is_bounded_and_named():
    """Uniform noise (every cell a candidate) and wide noise regions are capped, and the sidecar
    says which cap bit; a typical scene is not capped."""
    import numpy as np

    from thermcap.recorder.analysis.detector import HotSpotDetector
    from thermcap.recorder.capture.sources.sim import SimSource
    from thermcap.recorder.icd.sidecar import SIDECAR_SCHEMA

    model = SimSource(frames=1).model
    rng = np.random.default_rng(1)
    det = HotSpotDetector(model)
    dets, analysis = det.detect(rng.integers(0, 16383, (256, 320), dtype=np.uint16))
    assert dets == [] and analysis["detection_capped"]["rule"] == "candidate_cell_fraction"
    det = HotSpotDetector(model, max_regions=3)
    _, analysis = det.detect((2000 + rng.normal(0, 45, (256, 320))).astype(np.uint16))
    capped = analysis["detection_capped"]
    assert capped["rule"] == "max_regions" and capped["examined"] <= 3
    # the default cap is per 640x512 frame, in proportion to the area: a quarter of it here, so a
    # file source of this size is not held by the detector on a noisy scene (issue 40)
    _, analysis = HotSpotDetector(model).detect((2000 + rng.normal(0, 45, (256, 320))).astype(np.uint16))
    assert analysis["detection_capped"]["limit"] == 8 and analysis["detection_capped"]["examined"] <= 8
    assert "detection_capped" in SIDECAR_SCHEMA["properties"]["thermal_analysis"]["properties"]
    typical = SimSource(frames=5, paced=False, seed=3, start_time_ns=0)
    det = HotSpotDetector(typical.model, bad_pixel_map=typical.bad_pixel_map)
    assert all("detection_capped" not in det.detect(f.pixels)[1] for f in typical.frames())
