"""The detector's fast paths give what the plain ones give: working on counts for a linear
model (against the same model seen as a curve), labelling small windows side by side (against
one scipy call per window), and every region's facts at once (against find_objects)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from thermcap.recorder.analysis import detector_kernels
from thermcap.recorder.analysis.detector import HotSpotDetector, _components, _most_prominent, _region_stats
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.radiometry import LinearModel


class _SameLineAsACurve:
    """A linear model the detector does not recognise as one: it takes the whole-frame path."""

    kind = "curve"

    def __init__(self, model: LinearModel) -> None:
        self.model = model

    def to_celsius(self, raw: np.ndarray) -> np.ndarray:
        out = raw.astype(np.float32)
        out *= np.float32(self.model.scale_c_per_count)
        out += np.float32(self.model.offset_c)
        return out


def _run(det: HotSpotDetector, frames: list[np.ndarray]) -> list:
    return [([d.to_sidecar() for d in dets], analysis) for dets, analysis in map(det.detect, frames)]


def test_counts_and_temperatures_find_the_same_targets():
    src = SimSource(width=320, height=256, frames=10, seed=9)
    frames = [f.pixels.copy() for f in src.frames()]
    rng = np.random.default_rng(1)
    frames += [(2000 + rng.normal(0, 45, (256, 320))).astype(np.uint16) for _ in range(3)]
    on_counts = _run(HotSpotDetector(src.model), frames)
    on_temps = _run(HotSpotDetector(_SameLineAsACurve(src.model)), frames)  # type: ignore[arg-type]
    assert any(dets for dets, _ in on_counts)
    assert on_counts == on_temps


def _per_window(windows, min_area):
    out = []
    for y0, x0, m in windows:
        labels, n = ndimage.label(m, structure=ndimage.generate_binary_structure(2, 1))
        areas = np.bincount(labels.ravel(), minlength=n + 1)
        for i, sl in enumerate(ndimage.find_objects(labels), start=1):
            if areas[i] >= min_area:
                out.append((y0, x0, int(areas[i]), sl, labels[sl] == i))
    return out


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 80), st.integers(1, 30), st.floats(0.1, 0.7)), min_size=1, max_size=12),
       st.integers(1, 5), st.integers(0, 2**32 - 1))
def test_windows_labelled_together_match_one_call_each(shapes, min_area, seed):
    rng = np.random.default_rng(seed)
    windows = [(int(rng.integers(0, 500)), int(rng.integers(0, 600)), rng.random((h, w)) < p) for h, w, p in shapes]
    got = _components(windows, ndimage.generate_binary_structure(2, 1), min_area)
    want = _per_window(windows, min_area)
    assert len(got) == len(want)
    for g, e in zip(got, want, strict=True):
        assert g[:4] == e[:4]
        assert np.array_equal(g[4], e[4])


def _labelled_grid(h: int, w: int, p: float, seed: int):
    """A random candidate grid, its cells' excess and maxima, and scipy's 8-connected labels."""
    rng = np.random.default_rng(seed)
    cells = rng.random((h, w)) < p
    excess, cmax = rng.random((h, w)).astype(np.float32), rng.random((h, w)).astype(np.float32)
    regions, n = ndimage.label(cells, structure=np.ones((3, 3), bool))
    return cells, excess, cmax, regions, n


def _box(stats, k: int) -> tuple[int, int, int, int]:
    """Region ``k``'s box (in cells: y0, y1, x0, x1), as find_objects gives it."""
    i = k - 1
    return int(stats.y0[i]), int(stats.y1[i]), int(stats.x0[i]), int(stats.x1[i])


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.floats(0.05, 0.8), st.integers(0, 2**32 - 1))
def test_region_facts_match_find_objects_and_labelled_maxima(h, w, p, seed):
    cells, excess, cmax, regions, n = _labelled_grid(h, w, p, seed)
    stats = _region_stats(cells, regions, n, excess, cmax)
    objects = ndimage.find_objects(regions)
    assert [_box(stats, k) for k in range(1, n + 1)] == \
        [(o[0].start, o[0].stop, o[1].start, o[1].stop) for o in objects]
    if n:
        idx = np.arange(1, n + 1)
        assert np.array_equal(stats.top_excess, np.asarray(ndimage.maximum(excess, regions, idx), np.float32))
        assert np.array_equal(stats.top_cmax, np.asarray(ndimage.maximum(cmax, regions, idx), np.float32))


needs_numba = pytest.mark.skipif(not detector_kernels.available(),
                                 reason="numba is not installed: pip install 'thermcap[archive]'")


@needs_numba
@settings(max_examples=80, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.floats(0.05, 0.9), st.integers(0, 2**32 - 1))
def test_compiled_regions_are_scipys_labels_and_facts(h, w, p, seed):
    cells, excess, cmax, regions, n = _labelled_grid(h, w, p, seed)
    want = _region_stats(cells, regions, n, excess, cmax)
    got_n, got = detector_kernels.region_facts(cells, excess, cmax)
    assert got_n == n
    for a, b in zip((want.y0, want.y1, want.x0, want.x1, want.top_excess, want.top_cmax), got, strict=True):
        assert np.array_equal(a, b)


@needs_numba
@settings(max_examples=40, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.integers(0, 2**32 - 1))
def test_compiled_cell_grid_is_the_strided_one(ch, cw, seed):
    counts = np.random.default_rng(seed).integers(0, 2**16, (ch * 4, cw * 4), dtype=np.uint16)
    mean, cmax = detector_kernels.cell_mean_max(counts, 4)
    cells = counts.reshape(ch, 4, cw, 4)
    assert np.array_equal(cmax, cells.max(axis=(1, 3)))
    assert np.array_equal(mean, (cells.astype(np.float64).sum(axis=(1, 3)) / 16).astype(np.float32))


@needs_numba
@settings(max_examples=100, deadline=None)
@given(st.integers(1, 70), st.integers(1, 70), st.integers(1, 41), st.sampled_from([1, 45, 16383]),
       st.integers(0, 2**32 - 1))
def test_compiled_opening_is_the_doubling_windows(h, w, k, spread, seed):
    """The background's opening by van Herk's blocks equals ``sliding_extreme``'s minimum then
    maximum to the bit: windows wider than the grid, k = 1, even k, ties (a spread of 1),
    grids of one row or column."""
    from thermcap.recorder.analysis.detector import sliding_extreme

    mean = (np.random.default_rng(seed).integers(0, spread + 1, (h, w)) / np.float32(16)).astype(np.float32)
    want = sliding_extreme(sliding_extreme(mean, k, np.minimum), k, np.maximum)
    assert np.array_equal(detector_kernels.opening(mean, k), want)


@needs_numba
@settings(max_examples=80, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.sampled_from([0.036, 0.01, 1.0, 0.0123456]),
       st.sampled_from([-40.0, 0.0, -273.15, 12.3456]), st.sampled_from([5.0, 5.1, 0.3, 1e-3]),
       st.integers(0, 2**32 - 1))
def test_compiled_grid_excess_is_the_numpy_steps(ch, cw, scale, offset, thr, seed):
    """The grids in temperatures, the excess and the candidate cells to the bit: a threshold
    float32 cannot hold (5.1) is compared as numpy compares it, in float32."""
    from thermcap.recorder.analysis.detector import _affine32

    rng = np.random.default_rng(seed)
    cmax = rng.integers(0, 2**14, (ch, cw), dtype=np.uint16)
    mean = (cmax - rng.integers(0, 300, (ch, cw))).clip(0).astype(np.float32) + np.float32(0.0625)
    opened = (mean - rng.integers(0, 200, (ch, cw))).clip(0).astype(np.float32)
    affine = (np.float32(scale), np.float32(offset))
    want = [_affine32(a, *affine) for a in (opened, mean, cmax)]
    excess = want[2] - want[0]
    cells = excess >= thr
    got = detector_kernels.grid_excess(opened, mean, cmax, *affine, thr)
    for a, b in zip([*want, excess, cells], got[:5], strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert got[5] == int(np.count_nonzero(cells))


@needs_numba
def test_compiled_grid_excess_compares_as_numpy_does_at_a_threshold_float32_cannot_hold():
    """An excess of exactly float32(5.1), which is below 5.1: numpy compares a float32 array with
    a Python float in float32 and calls it a candidate; a float64 comparison would not."""
    thr = 5.1
    cmax = np.full((2, 3), 8, np.uint16)
    opened = np.full((2, 3), np.float32(8) - np.float32(thr), np.float32)  # exact (Sterbenz)
    opened[1, 2] = np.nextafter(opened[1, 2], np.float32(9))  # just short of the threshold
    got = detector_kernels.grid_excess(opened, opened, cmax, np.float32(1.0), np.float32(0.0), thr)
    assert got[3][0, 0] == np.float32(thr) and float(got[3][0, 0]) < thr
    assert np.array_equal(got[4], (cmax.astype(np.float32) - opened) >= thr)
    assert got[4].tolist() == [[True, True, True], [True, True, False]] and got[5] == 5


@needs_numba
@settings(max_examples=80, deadline=None)
@given(st.integers(1, 70), st.integers(1, 70), st.integers(1, 41), st.sampled_from([0.01, 1.0, 45.0, 3000.0]),
       st.booleans(), st.integers(0, 2**32 - 1))
def test_compiled_local_mean_is_scipys_uniform_filter(h, w, size, spread, celsius, seed):
    grid = (2000 + np.random.default_rng(seed).normal(0, spread, (h, w))).astype(np.float32)
    if celsius:
        grid = grid * np.float32(0.036) - np.float32(40)
    want = ndimage.uniform_filter(grid, size=size, mode="nearest")
    assert np.array_equal(detector_kernels.box_mean(grid, size), want)


@needs_numba
@settings(max_examples=150, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.floats(0.0, 1.0), st.floats(0.0, 0.2), st.booleans(),
       st.integers(0, 2**32 - 1))
def test_compiled_bad_pixel_mending_is_the_numpy_medians(h, w, bad_share, nan_share, few_values, seed):
    """Each bad pixel the median of its good 3x3 neighbours, to the bit: odd and even counts
    (the two middle values' float32 sum halved), at the frame's edges and corners, beside other
    bad pixels, with none good, with ties (few distinct values) and with NaN."""
    from unittest import mock

    rng = np.random.default_rng(seed)
    temps = (rng.integers(0, 4, (h, w)) * np.float32(0.5) if few_values
             else rng.normal(20, 30, (h, w))).astype(np.float32)
    temps[rng.random((h, w)) < nan_share] = np.nan
    bad = rng.random((h, w)) < bad_share
    det = HotSpotDetector(LinearModel(), bad_pixel_map=bad)
    compiled = det._fix_bad_pixels(temps)
    with mock.patch.object(detector_kernels, "available", return_value=False):
        plain = HotSpotDetector(LinearModel(), bad_pixel_map=bad)._fix_bad_pixels(temps)
    assert np.array_equal(compiled, plain, equal_nan=True)
    assert np.array_equal(compiled[~bad], temps[~bad], equal_nan=True)  # only the bad pixels change


def test_a_bad_pixel_map_assigned_later_is_the_one_mended():
    """The bad pixels' coordinates were taken from the first map a detector mended with and kept
    when another map was assigned: the new map's pixels were left as they were, and the old
    ones mended."""
    temps = np.full((16, 16), 20.0, np.float32)
    temps[5, 5] = temps[10, 10] = 90.0
    first, second = np.zeros((16, 16), bool), np.zeros((16, 16), bool)
    first[5, 5] = second[10, 10] = True
    det = HotSpotDetector(LinearModel(), bad_pixel_map=first)
    assert det._fix_bad_pixels(temps)[5, 5] == 20.0
    det.bad_pixel_map = second
    mended = det._fix_bad_pixels(temps)
    assert mended[10, 10] == 20.0 and mended[5, 5] == 90.0
    det.bad_pixel_map = np.zeros((16, 16), bool)  # none bad: the frame as it came
    assert det._fix_bad_pixels(temps) is temps


def _prominent_by_full_sort(top_excess, boxes, limit, budget):
    """The region choice as the detector first wrote it: every region sorted, then taken in turn."""
    chosen, spent = [], 0
    for k in (int(j) + 1 for j in np.argsort(-top_excess, kind="stable")):
        if len(chosen) >= limit:
            break
        if spent + boxes[k - 1] > budget:
            continue
        chosen.append(k)
        spent += boxes[k - 1]
    return chosen


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 400), st.integers(0, 40), st.integers(1, 6), st.floats(0.0, 1.0), st.floats(0.0, 0.2),
       st.integers(0, 2**32 - 1))
def test_most_prominent_regions_are_the_full_sorts(n, limit, levels, budget_share, nan_share, seed):
    """Few distinct values (ties at the partition's edge), boxes that overspend the budget (the
    head runs out before the limit), and NaN (a temperature model's), against sorting them all."""
    rng = np.random.default_rng(seed)
    top = rng.integers(0, levels, n).astype(np.float32)
    top[rng.random(n) < nan_share] = np.nan
    boxes = rng.choice([1, 2, 4, 9, 40, 400], n).tolist()  # a few wide boxes the budget passes over
    budget = budget_share * 25 * max(limit, 1)
    assert _most_prominent(top, boxes, limit, budget) == _prominent_by_full_sort(top, boxes, limit, budget)


@needs_numba
def test_detector_finds_the_same_with_and_without_the_compiled_passes(monkeypatch):
    src = SimSource(width=320, height=250, frames=12, seed=4)  # 250 rows: the last cells padded
    frames = [f.pixels.copy() for f in src.frames()]
    rng = np.random.default_rng(2)
    frames += [(2000 + rng.normal(0, 45, (250, 320))).astype(np.uint16) for _ in range(3)]
    frames += [rng.integers(0, 16383, (250, 320), dtype=np.uint16)]
    compiled = _run(HotSpotDetector(src.model), frames)
    monkeypatch.setattr(detector_kernels, "available", lambda: False)
    plain = _run(HotSpotDetector(src.model), frames)
    assert any(dets for dets, _ in compiled)
    assert any("detection_capped" in a for _, a in compiled)
    assert compiled == plain


@needs_numba
@pytest.mark.parametrize("h, w", [(1, 1), (1, 7), (7, 1), (9, 11), (40, 39)])
def test_compiled_regions_take_the_most_regions_a_grid_can_hold(h, w):
    cells = np.zeros((h, w), bool)
    cells[::2, ::2] = True  # isolated cells, one per 2x2 block: every one a new label
    excess = np.arange(h * w, dtype=np.float32).reshape(h, w)
    regions, n = ndimage.label(cells, structure=np.ones((3, 3), bool))
    want = _region_stats(cells, regions, n, excess, excess)
    got_n, got = detector_kernels.region_facts(cells, excess, excess)
    assert got_n == n == ((h + 1) // 2) * ((w + 1) // 2)
    assert all(np.array_equal(a, b) for a, b in zip((want.y0, want.y1, want.x0, want.x1), got, strict=False))


def test_kernels_that_cannot_run_leave_the_numpy_path(monkeypatch):
    def broken(*_args):
        raise RuntimeError("no compiler for this machine")

    monkeypatch.setattr(detector_kernels, "cell_mean_max", broken)
    monkeypatch.setattr(detector_kernels, "_usable", None)
    assert detector_kernels.available() is False
    src = SimSource(width=160, height=128, frames=4, seed=4)
    frames = [f.pixels.copy() for f in src.frames()]
    assert any(dets for dets, _ in _run(HotSpotDetector(src.model), frames))


def _both_window_paths(det: HotSpotDetector, src, opened, boxes, affine):
    """The detector's window stage through the compiled pass and through numpy and scipy."""
    from unittest import mock

    from thermcap.recorder.analysis.detector import _affine32

    f = det._F
    h, w = src.shape
    ph, pw = -(-h // f) * f, -(-w // f) * f
    padded = np.pad(src, ((0, ph - h), (0, pw - w)), mode="edge")
    celsius = (lambda a: _affine32(a, *affine)) if affine is not None else (lambda a: a)
    compiled = det._window_components(src, padded, opened, boxes, affine, celsius)
    with mock.patch.object(detector_kernels, "available", lambda: False):
        plain = det._window_components(src, padded, opened, boxes, affine, celsius)
    return compiled, plain


@needs_numba
@settings(max_examples=80, deadline=None)
@given(st.integers(4, 70), st.integers(4, 70), st.lists(st.tuples(st.integers(0, 20), st.integers(1, 8),
                                                                    st.integers(0, 20), st.integers(1, 8)),
                                                          min_size=1, max_size=10),
       st.sampled_from([5.0, 4.1, 0.3]), st.integers(1, 6), st.booleans(), st.integers(0, 2**32 - 1))
def test_compiled_windows_are_the_numpy_masks_and_scipys_components(h, w, spans, thr, min_area, counts, seed):
    rng = np.random.default_rng(seed)
    ch, cw = -(-h // 4), -(-w // 4)
    boxes = []
    for y0, dy, x0, dx in spans:  # boxes in cells, inside the grid (the last row and column may be padding)
        y0, x0 = min(y0, ch - 1), min(x0, cw - 1)
        boxes.append((y0, min(ch, y0 + dy), x0, min(cw, x0 + dx)))
    det = HotSpotDetector(LinearModel(), threshold_k=thr, min_area=min_area)
    if counts:  # uint16 counts through the model's float32 map, against a background in °C
        src = (2000 + rng.normal(0, 45, (h, w))).astype(np.uint16)
        affine = (np.float32(0.036), np.float32(-40.0))
        opened = (32.0 + rng.normal(0, 1, (ch, cw))).astype(np.float32)
    else:  # temperatures already (a curve, a bad-pixel map)
        src = (30.0 + rng.normal(0, 2, (h, w))).astype(np.float32)
        affine = None
        opened = (30.0 + rng.normal(0, 1, (ch, cw))).astype(np.float32)
    compiled, plain = _both_window_paths(det, src, opened, boxes, affine)
    assert len(compiled) == len(plain)
    for g, e in zip(compiled, plain, strict=True):
        assert g[:4] == e[:4]
        assert np.array_equal(g[4], e[4])


@needs_numba
@pytest.mark.parametrize("h, w", [(4, 4), (5, 9), (33, 17), (64, 64)])
def test_compiled_windows_take_the_most_components_a_box_can_hold(h, w):
    """A checkerboard: every candidate pixel a component of its own (4-connected), the most labels
    a window can need; with min_area 1 every one is kept."""
    src = np.zeros((h, w), np.float32)
    src[(np.arange(h)[:, None] + np.arange(w)[None, :]) % 2 == 0] = 10.0
    ch, cw = -(-h // 4), -(-w // 4)
    det = HotSpotDetector(LinearModel(), threshold_k=5.0, min_area=1)
    boxes = [(0, ch, 0, cw), (0, 1, 0, 1)]
    compiled, plain = _both_window_paths(det, src, np.zeros((ch, cw), np.float32), boxes, None)
    assert len(compiled) == len(plain) == (h * w + 1) // 2 + 8
    assert all(g[:4] == e[:4] and np.array_equal(g[4], e[4]) for g, e in zip(compiled, plain, strict=True))


def _blob_frame(h, w, level, amplitude, y, x, size, noise, seed):
    rng = np.random.default_rng(seed)
    frame = np.full((h, w), level, np.float64) + rng.normal(0, noise, (h, w))
    frame[y:y + size, x:x + size] += amplitude
    return np.clip(np.rint(frame), 0, 65535).astype(np.uint16)


@settings(max_examples=120, deadline=None)
@given(st.integers(8, 90), st.integers(8, 90), st.integers(500, 9000), st.floats(120.0, 160.0),
       st.integers(0, 80), st.integers(0, 80), st.integers(1, 12), st.sampled_from([0.0, 0.4, 2.0]),
       st.booleans(), st.integers(0, 2**32 - 1))
def test_a_frame_too_flat_for_any_candidate_answers_as_the_full_path(h, w, level, amplitude, y, x, size, noise,
                                                                     as_curve, seed):
    """The early answer for a low-contrast frame (its warmest cell within the threshold of its
    coldest mean) is the full path's, at the threshold's edge: a blob of 120-160 counts (the
    threshold is 139 counts at 0.036 K a count), on counts and on temperatures."""
    frame = _blob_frame(h, w, level, amplitude, min(y, h - 1), min(x, w - 1), size, noise, seed)
    model = LinearModel()
    early, full = (HotSpotDetector(_SameLineAsACurve(model) if as_curve else model) for _ in range(2))  # type: ignore[arg-type]
    full._too_flat = lambda *_a: False  # type: ignore[method-assign]
    assert _run(early, [frame]) == _run(full, [frame])


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 90), st.integers(1, 90), st.integers(500, 9000), st.floats(0.0, 200.0),
       st.integers(0, 80), st.integers(0, 80), st.integers(1, 12), st.sampled_from([0.0, 0.4, 2.0]),
       st.integers(0, 2**32 - 1))
def test_a_flat_answer_is_given_only_where_detect_gives_it_and_is_the_same(h, w, level, amplitude, y, x, size, noise,
                                                                          seed):
    """``flat_answer`` (what the recorder answers without the detector's process) is never
    given for a frame ``detect`` answers otherwise, is ``detect``'s answer when given, and is
    given for every frame within the threshold (139 counts at 0.036 K a count)."""
    frame = _blob_frame(h, w, level, amplitude, min(y, h - 1), min(x, w - 1), size, noise, seed)
    det = HotSpotDetector(LinearModel())
    flat = det.flat_answer(frame)
    span = int(frame.max()) - int(frame.min())
    if span <= 138:
        assert flat is not None
    if flat is not None:
        assert _run(HotSpotDetector(LinearModel()), [frame]) == [([], flat[1])]
        assert flat[0] == []


def test_a_flat_answer_is_left_to_detect_for_a_curve_bad_pixels_or_a_warm_spot_between_sampled_rows():
    flat = np.full((256, 320), 2000, np.uint16)
    model = LinearModel()
    assert HotSpotDetector(model).flat_answer(flat) is not None
    assert HotSpotDetector(_SameLineAsACurve(model)).flat_answer(flat) is None  # type: ignore[arg-type]
    bad = np.zeros(flat.shape, bool)
    bad[10, 10] = True
    assert HotSpotDetector(model, bad_pixel_map=bad).flat_answer(flat) is None
    assert HotSpotDetector(model).flat_answer(flat.astype(np.float32)) is None
    spot = flat.copy()
    spot[100:103, 50:53] += 400  # rows 100-102: none of them sampled (every 64th row)
    assert HotSpotDetector(model).flat_answer(spot) is None
    assert [d.bbox for d in HotSpotDetector(model).detect(spot)[0]] == [[50, 100, 52, 102]]  # found, not hidden


def test_the_early_answer_is_taken_at_the_thresholds_edge_and_not_past_it():
    model = LinearModel()
    below, above = (_blob_frame(64, 64, 2000, a, 20, 20, 8, 0.0, 1) for a in (138, 140))
    det = HotSpotDetector(model)
    mean, cmax, _ = det._cells(below)
    assert det._too_flat(mean, cmax, (np.float32(model.scale_c_per_count), np.float32(model.offset_c)))
    mean, cmax, _ = det._cells(above)
    assert not det._too_flat(mean, cmax, (np.float32(model.scale_c_per_count), np.float32(model.offset_c)))


def test_a_uniform_frame_costs_the_cell_grid_alone(monkeypatch):
    """A wall, fog, the sea, a lens cap: no opening is computed (it was half of a flat frame)."""
    det = HotSpotDetector(LinearModel())

    def no_opening(_mean, counts=False):
        raise AssertionError("the opening was computed for a frame with no possible candidate")

    monkeypatch.setattr(det, "_opening", no_opening)
    dets, analysis = det.detect(np.full((512, 640), 2000, np.uint16))
    assert dets == [] and "detection_capped" not in analysis


def test_the_background_leaves_a_warm_target_out_and_keeps_the_frames_size():
    """``background`` (the opening of the cell grid at full resolution) is what the candidates
    stand above: a 20 K target on a 20 C wall must not raise it, and a frame that is not a whole
    number of cells keeps its size."""
    det = HotSpotDetector(SimSource(frames=1).model)
    temps = np.full((61, 83), 20.0, np.float32)
    temps[20:28, 30:38] = 40.0
    bg = det.background(temps)
    assert bg.shape == temps.shape
    assert np.allclose(bg, 20.0)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.floats(0.05, 0.9), st.floats(0.0, 0.3), st.integers(0, 2**32 - 1))
def test_regions_standing_out_are_the_per_region_tests(h, w, p, nan_share, seed):
    """All the examined regions at once give the boxes the loop over each region gave, in the
    same order; a NaN local mean (the temperature path) keeps its region, as before."""
    from thermcap.recorder.analysis.detector import _regions

    rng = np.random.default_rng(seed)
    cells = rng.random((h, w)) < p
    excess = rng.normal(3.0, 3.0, (h, w)).astype(np.float32)
    cmax = rng.normal(30.0, 4.0, (h, w)).astype(np.float32)
    local_mean = rng.normal(26.0, 2.0, (h, w)).astype(np.float32)
    local_mean[rng.random((h, w)) < nan_share] = np.nan
    n, stats = _regions(cells, excess, cmax, np.ones((3, 3), bool))
    det = HotSpotDetector(LinearModel())
    examine = sorted(rng.choice(np.arange(1, n + 1), size=min(n, 32), replace=False).tolist()) if n else []
    want = []
    for k in examine:
        cy0, cy1, cx0, cx1 = _box(stats, k)
        cy, cx = min((cy0 + cy1) // 2, h - 1), min((cx0 + cx1) // 2, w - 1)
        if stats.top_cmax[k - 1] - local_mean[cy, cx] < 0.8 * det.threshold_k:
            continue
        want.append((cy0, cy1, cx0, cx1))
    assert det._standing_out(stats, examine, local_mean) == want


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.floats(0.0, 0.4), st.integers(0, 3), st.integers(0, 2**32 - 1))
def test_the_background_ring_dilation_is_scipys(h, w, p, iterations, seed):
    """The ring a target is graded against leaves out the target and its warm neighbours grown
    by two pixels: numpy's cross dilation gives scipy's binary_dilation to the pixel, edges included."""
    from thermcap.recorder.analysis.detector import _dilated

    mask = np.random.default_rng(seed).random((h, w)) < p
    cross = ndimage.generate_binary_structure(2, 1)
    want = ndimage.binary_dilation(mask, structure=cross, iterations=iterations) if iterations else mask
    assert np.array_equal(_dilated(mask, iterations), want)


def test_importing_the_recorder_imports_neither_scipy_nor_numba():
    """The recording process hands its frames to the detector's process, so neither library is
    loaded there before the first frame (together 0.6-1.3 s of every `thermcap record`'s start)."""
    import subprocess
    import sys

    code = ("import sys, thermcap.recorder.capture.recorder, thermcap.recorder.analysis.process_runner; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'numba'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
