"""The simulator: seeded, reproducible, and its scene and radar behave as documented."""

from __future__ import annotations

import numpy as np

from thermcap.recorder.capture.sources.sim import SimSource


def _frames(**kw):
    return list(SimSource(paced=False, start_time_ns=0, **kw).frames())


def test_same_seed_same_frames_bit_for_bit():
    a = _frames(frames=20, seed=7, width=160, height=128)
    b = _frames(frames=20, seed=7, width=160, height=128)
    for fa, fb in zip(a, b, strict=True):
        assert np.array_equal(fa.pixels, fb.pixels)
        assert fa.sidecar == fb.sidecar
        assert fa.messages == fb.messages


def test_different_seed_different_frames():
    a = _frames(frames=2, seed=1, width=160, height=128)
    b = _frames(frames=2, seed=2, width=160, height=128)
    assert not np.array_equal(a[1].pixels, b[1].pixels)


def test_frames_are_14_bit_gray16_with_the_listed_bad_pixels():
    src = SimSource(paced=False, frames=3, width=640, height=512)
    frames = list(src.frames())
    f = frames[0].pixels
    assert f.dtype == np.uint16
    assert f.shape == (512, 640)
    assert f.max() <= 16383
    bad = src.bad_pixel_map
    assert bad.sum() > 0
    assert set(np.unique(f[bad])) <= {0, 16383}


def test_temporal_noise_matches_netd():
    src = SimSource(paced=False, frames=2, width=320, height=256, netd_mk=50.0)
    a, b = [f.pixels.astype(float) for f in src.frames()]
    good = ~src.bad_pixel_map
    # Two frames of a static background: their difference has sqrt(2) times the temporal noise.
    diff = (a - b)[200:, :][good[200:, :]]  # ground rows, away from moving targets mostly
    diff = diff[np.abs(diff) < 15]  # a moving target's edge is not noise
    netd = diff.std() / np.sqrt(2) * 0.036 * 1000
    assert 40 < netd < 60


def test_targets_are_warm_and_truth_matches_pixels():
    f = _frames(frames=1, width=640, height=512)[0]
    drone = next(t for t in f.sidecar["targets"] if t["classification"] == "drone_motor")
    assert 40 <= drone["max_temp_c"] <= 52
    x0, y0, x1, y1 = drone["bbox"]
    patch = f.pixels[y0:y1 + 1, x0:x1 + 1] * 0.036 - 40
    assert patch.max() == np.float64(drone["max_temp_c"]) or abs(patch.max() - drone["max_temp_c"]) < 1e-6
    assert f.sidecar["thermal_analysis"]["thermal_contrast_grade"] == 1.0


def test_crossover_fades_contrast_below_0_3_and_back():
    frames = _frames(frames=240, fps=60, crossover=True, width=160, height=128)
    grades = [f.sidecar["thermal_analysis"]["thermal_contrast_grade"] for f in frames]
    assert grades[0] == 1.0
    assert grades[-1] == 1.0
    assert min(grades) < 0.3
    assert sum(g < 0.3 for g in grades) > 30  # a span, not a blip


def test_slew_to_cue_walks_the_state_machine():
    frames = _frames(frames=60 * 9, fps=60, width=160, height=128, cue_period_s=20.0)
    states = [f.sidecar["slew_to_cue"]["state"] for f in frames]
    seen = [s for i, s in enumerate(states) if i == 0 or states[i - 1] != s]
    assert seen == ["idle", "slew", "search", "lock", "handoff", "idle"]
    cues = [m for f in frames for t, m in f.messages if t == "/radar/cue"]
    assert cues
    assert cues[0]["target_id"] == "TRK001"
    active = [f.sidecar["slew_to_cue"]["slew_to_cue_active"] for f in frames]
    assert active[states.index("search")]
    assert not active[0]
    search = [f.sidecar["slew_to_cue"] for f in frames if f.sidecar["slew_to_cue"]["state"] == "search"]
    assert all(s["search_pattern_active"] for s in search)
    assert all(abs(s["turret_pan_deg"] - s["radar_azimuth_deg"]) <= 2.01 for s in search)


def test_large_frames_supported():
    f = _frames(frames=1, width=1280, height=1024)[0]
    assert f.pixels.shape == (1024, 1280)
