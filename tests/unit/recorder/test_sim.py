"""The simulator: seeded, reproducible, and its scene and radar behave as documented."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_shake_moves_the_picture_by_a_fraction_of_a_pixel_and_not_the_sensor_pattern():
    kw = {"frames": 6, "seed": 3, "width": 160, "height": 128, "netd_mk": 0.0, "bad_pixels": 0, "targets": ()}
    still = _frames(**kw)
    shaken = _frames(**kw, shake_px=0.5)
    again = _frames(**kw, shake_px=0.5)
    src = SimSource(paced=False, **kw, shake_px=0.5)
    for i, (a, b, c) in enumerate(zip(still, shaken, again, strict=True)):
        assert np.array_equal(b.pixels, c.pixels)  # a function of the seed and the index
        dx, dy = src.shake(i)
        assert 0 < max(abs(dx), abs(dy)) <= 0.5
        diff = np.abs(a.pixels.astype(int) - b.pixels.astype(int))
        assert diff.max() > 0  # it moved
        # by less than a pixel: each shaken count lies between its neighbours' unshaken ones (a
        # bilinear blend of them), the pattern (column FPN here) staying with the sensor
        scene = a.pixels.astype(float) - src._fpn_counts
        lo = np.minimum.reduce([np.roll(scene, (sy, sx), (0, 1)) for sy in (-1, 0, 1) for sx in (-1, 0, 1)])
        hi = np.maximum.reduce([np.roll(scene, (sy, sx), (0, 1)) for sy in (-1, 0, 1) for sx in (-1, 0, 1)])
        got = b.pixels.astype(float) - src._fpn_counts
        inner = (slice(2, -2), slice(2, -2))
        assert np.all(got[inner] >= lo[inner] - 1.0) and np.all(got[inner] <= hi[inner] + 1.0)


def test_gain_steps_scale_the_frame_about_its_mean_level_at_each_period():
    kw = {"frames": 130, "seed": 4, "width": 64, "height": 48, "fps": 60.0, "bad_pixels": 0}
    plain = _frames(**kw)
    stepped = _frames(**kw, gain_every_s=1.0, gain_step=0.1)
    src = SimSource(paced=False, **kw, gain_every_s=1.0, gain_step=0.1)
    assert [src.gain(i) for i in (0, 59)] == [1.0, 1.0]
    assert src.gain(60) == src.gain(119) != 1.0 and src.gain(120) != src.gain(60)
    assert all(abs(src.gain(i) - 1) <= 0.1 for i in range(130))
    assert np.array_equal(plain[10].pixels, stepped[10].pixels)  # before the first step
    pivot = float(src._background_counts.mean())
    for i in (60, 125):
        a, b = plain[i].pixels.astype(float), stepped[i].pixels.astype(float)
        assert np.allclose(b - pivot, (a - pivot) * src.gain(i), atol=1.1)  # rounding only (before and after the gain)


def test_shake_and_gain_refuse_absurd_values():
    import pytest

    with pytest.raises(ValueError, match="shake_px"):
        SimSource(frames=1, shake_px=20.0)
    with pytest.raises(ValueError, match="gain"):
        SimSource(frames=1, gain_every_s=0.0)


def test_row_runs_repeat_the_left_neighbour_in_runs_that_change_every_frame():
    kw = {"frames": 3, "seed": 6, "width": 160, "height": 128, "bad_pixels": 0}
    plain = _frames(**kw)
    runs = _frames(**kw, row_runs=0.6)
    assert np.array_equal(runs[0].pixels, _frames(**kw, row_runs=0.6)[0].pixels)  # a function of the seed
    for a, b in zip(plain, runs, strict=True):
        p, r = a.pixels, b.pixels
        assert np.array_equal(r[:, 0], p[:, 0])
        share = float((r[:, 1:] == r[:, :-1]).mean()) - float((p[:, 1:] == p[:, :-1]).mean())
        assert 0.5 < share < 0.65, share
        # every value is the frame's own, from its row, at or left of its column
        cols = np.arange(p.shape[1])
        for y in (0, 64, 127):
            src = [int(np.flatnonzero(p[y, :x + 1] == v)[-1]) if (p[y, :x + 1] == v).any() else -1
                   for x, v in zip(cols, r[y], strict=True)]
            assert min(src) >= 0
    masks = [(b.pixels[:, 1:] == b.pixels[:, :-1]) for b in runs]
    assert not np.array_equal(masks[0], masks[1])
    with pytest.raises(ValueError, match="row_runs"):
        SimSource(frames=1, row_runs=1.0)


def test_each_flat_field_correction_leaves_a_new_frame_wide_offset():
    kw = {"frames": 130, "seed": 4, "width": 64, "height": 48, "fps": 60.0, "bad_pixels": 0, "shutter_every_s": 1.0}
    plain = _frames(**kw)
    stepped = _frames(**kw, nuc_step_counts=20.0)
    src = SimSource(paced=False, **kw, nuc_step_counts=20.0)
    assert src.nuc_offset(59) == 0.0 and src.nuc_offset(60) == src.nuc_offset(119) != src.nuc_offset(120)
    assert all(abs(src.nuc_offset(i)) <= 20.0 for i in range(130))
    assert np.array_equal(plain[30].pixels, stepped[30].pixels)  # before the first correction
    assert np.array_equal(plain[61].pixels, stepped[61].pixels)  # the shutter itself: a uniform field
    for i in (70, 125):
        d = stepped[i].pixels.astype(float) - plain[i].pixels.astype(float)
        # the same picture moved by the offset (each rounded to counts on its own)
        assert np.abs(d - src.nuc_offset(i)).max() < 1.0 and abs(d.mean() - src.nuc_offset(i)) < 0.1
    with pytest.raises(ValueError, match="nuc_step_counts"):
        SimSource(frames=1, nuc_step_counts=5.0)  # no shutter, no correction
