"""Hot-spot detection for every source, the ICD contrast metrics from real masks, and events.

The detector works on temperatures (through the session's radiometric model), against a
*local* background: a grey opening wider than any target (``max_size``), which removes warm
objects but keeps edges such as the horizon. (A global mean + 1 sigma, tried on a real DJI
frame, gave 1,794 peaks for 28 animals.) Candidates stand at least ``threshold_k`` (the ICD's
5 K detection threshold) above that background; a connected component of at least
``min_area`` pixels is a target if its peak also stands ``threshold_k`` and ``min_sigma`` ring
deviations above the median of the ring around it, which rejects texture and slopes. Targets
are tracked across frames by overlap.
Each target is graded against a ring of its own local background with ICD 7.1's exact code
(``quality.contrast_metrics``); the frame reports its most detectable target.
"""

from __future__ import annotations

import contextlib
import copy
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from thermcap.recorder.analysis import detector_kernels
from thermcap.recorder.icd.names import CROSSOVER_GRADE, DETECTION_THRESHOLD_K
from thermcap.recorder.icd.quality import contrast_metrics, frame_analysis, graded_contrast
from thermcap.recorder.radiometry import RadiometricModel

__all__ = ["Detection", "EventBuilder", "HotSpotDetector", "iou"]


@dataclass
class Detection:
    target_id: str
    bbox: list[int]  # [x_min, y_min, x_max, y_max], inclusive pixel coordinates
    centroid: list[float]  # [x, y]
    max_temp_c: float
    mean_temp_c: float
    confidence: float
    metrics: dict[str, Any]
    classification: str = "hot_spot"

    def to_sidecar(self) -> dict[str, Any]:
        return {"target_id": self.target_id, "bbox": self.bbox, "centroid": self.centroid,
                "max_temp_c": round(self.max_temp_c, 3), "mean_temp_c": round(self.mean_temp_c, 3),
                "classification": self.classification, "confidence": round(self.confidence, 3)}


def _ndimage() -> Any:
    """scipy.ndimage, imported where a numpy path needs it (without numba's kernels). Importing it
    at the top cost every ``thermcap record`` 0.4-0.9 s before its first frame, in a process that
    hands its frames to the detector's and runs none of it."""
    from scipy import ndimage

    return ndimage


def _dilated(mask: np.ndarray, iterations: int) -> np.ndarray:
    """``scipy.ndimage.binary_dilation(mask, structure=<the 4-connected cross>,
    iterations=iterations)``, nothing beyond the edges: each step adds every pixel's four
    neighbours. numpy alone, so a detector that finds a target needs no scipy."""
    out = mask.copy()
    for _ in range(iterations):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        out = grown
    return out


def iou(a: list[int], b: list[int]) -> float:
    """Intersection over union of two inclusive pixel boxes."""
    ix = min(a[2], b[2]) - max(a[0], b[0]) + 1
    iy = min(a[3], b[3]) - max(a[1], b[1]) + 1
    if ix <= 0 or iy <= 0:
        return 0.0
    inter = ix * iy
    area = lambda r: (r[2] - r[0] + 1) * (r[3] - r[1] + 1)  # noqa: E731
    return inter / (area(a) + area(b) - inter)


def _celsius32(model: RadiometricModel, raw: np.ndarray) -> np.ndarray:
    from thermcap.recorder.radiometry import LinearModel

    if isinstance(model, LinearModel):  # float32 all the way: half the memory traffic
        out = raw.astype(np.float32)
        out *= np.float32(model.scale_c_per_count)
        out += np.float32(model.offset_c)
        return out
    return np.asarray(model.to_celsius(raw), dtype=np.float32)


def _counts_affine(model: RadiometricModel) -> tuple[np.float32, np.float32] | None:
    """(scale, offset) in float32 where temperature is an increasing affine map of counts: then
    the coarse grid's minima and maxima commute with it, and the detector works on counts,
    converting only the grid and the windows it looks at (a whole-frame conversion was a fifth
    of a flat frame's cost)."""
    from thermcap.recorder.radiometry import LinearModel

    if isinstance(model, LinearModel) and model.scale_c_per_count > 0:
        return np.float32(model.scale_c_per_count), np.float32(model.offset_c)
    return None


def _affine32(a: np.ndarray, scale: np.float32, offset: np.float32) -> np.ndarray:
    """``_celsius32`` of a linear model, element by element the same float32 operations."""
    out = a.astype(np.float32)
    out *= scale
    out += offset
    return out


def _median(values: np.ndarray) -> float:
    """``float(np.median(values))`` of a 1-D float32 array, by one partition: np.median's own
    bookkeeping cost more than the partition on the detector's rings."""
    n = values.size
    if n % 2:
        return float(np.partition(values, n // 2)[n // 2])
    part = np.partition(values, (n // 2 - 1, n // 2))
    return float((part[n // 2 - 1] + part[n // 2]) / values.dtype.type(2))


def sliding_extreme(a: np.ndarray, k: int, op: np.ufunc) -> np.ndarray:
    """``op`` (np.minimum or np.maximum) over every k x k window of a 2-D array, edges
    repeated: exactly scipy's ``minimum_filter``/``maximum_filter(size=k, mode="nearest")``,
    in 2 log2(k) whole-array ops (windows double, then one last overlapping step), where
    scipy walks every line: 2.2x faster on the detector's coarse grid."""
    r = k // 2
    for axis in (0, 1):
        src = a if axis == 0 else a.T
        n = src.shape[0]
        cur = np.empty((n + k - 1, *src.shape[1:]), a.dtype)  # np.pad(mode="edge"), without its overhead
        cur[r:r + n] = src
        cur[:r] = src[0]
        cur[r + n:] = src[-1]
        if axis == 1:
            cur = cur.T
        span = 1
        while span < k:
            step = min(span, k - span)
            n = cur.shape[axis]
            cur = op(cur[(slice(None),) * axis + (slice(0, n - step),)], cur[(slice(None),) * axis + (slice(step, n),)])
            span += step
        a = cur
    return a


@dataclass(frozen=True)
class _RegionStats:
    """Per-region facts of a labelled coarse grid, in label order (label k at index k - 1)."""

    y0: np.ndarray
    y1: np.ndarray  # exclusive
    x0: np.ndarray
    x1: np.ndarray
    top_excess: np.ndarray  # the region's largest (cell max - background)
    top_cmax: np.ndarray  # the region's warmest cell

    def areas(self) -> list[int]:
        return ((self.y1 - self.y0) * (self.x1 - self.x0)).tolist()


def _region_stats(cells: np.ndarray, regions: np.ndarray, n: int, excess: np.ndarray,
                  cmax: np.ndarray) -> _RegionStats:
    """Boxes and maxima of every region at once, from its cells sorted by label: on a noisy
    frame (a thousand regions) scipy's find_objects and labelled maximum built a thousand
    Python objects and sorted the grid, and cost more than the detection itself."""
    ys, xs = np.nonzero(cells)  # the regions' cells (a boolean nonzero is the cheaper one)
    lab = regions[ys, xs]
    order = np.argsort(lab, kind="stable")
    ys, xs, lab = ys[order], xs[order], lab[order]
    starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]]) if lab.size else np.zeros(0, np.intp)
    assert starts.size == n  # ndimage.label numbers its regions 1..n, each with a cell
    red = lambda op, v: op.reduceat(v, starts) if n else np.zeros(0, v.dtype)  # noqa: E731
    return _RegionStats(y0=red(np.minimum, ys), y1=red(np.maximum, ys) + 1, x0=red(np.minimum, xs),
                        x1=red(np.maximum, xs) + 1, top_excess=red(np.maximum, excess[ys, xs]),
                        top_cmax=red(np.maximum, cmax[ys, xs]))


def _regions(cells: np.ndarray, excess: np.ndarray, cmax: np.ndarray,
             structure: np.ndarray) -> tuple[int, _RegionStats]:
    """The candidate cells' 8-connected regions and their facts: one compiled pass where numba
    is installed, else scipy's labels and ``_region_stats`` (the same answers)."""
    if detector_kernels.available():
        n, facts = detector_kernels.region_facts(cells, excess, cmax)
        return n, _RegionStats(*facts)
    regions, n = _ndimage().label(cells, structure=structure)
    return n, _region_stats(cells, regions, n, excess, cmax)


def _local_mean(cell_mean: np.ndarray, size: int) -> np.ndarray:
    """The mean around each coarse cell (``uniform_filter``, edges repeated), compiled where it can."""
    if cell_mean.dtype == np.float32 and detector_kernels.available():
        return detector_kernels.box_mean(cell_mean, size)
    return _ndimage().uniform_filter(cell_mean, size=size, mode="nearest")


def _pick(order: Any, boxes: list[int], limit: int, budget: float) -> tuple[list[int], bool]:
    """Labels from ``order`` (0-based region indices, most prominent first) until ``limit`` are
    chosen, passing over any whose box would overspend ``budget``: (chosen, whether ``limit``
    was reached)."""
    chosen: list[int] = []
    spent = 0
    for j in order:
        if len(chosen) >= limit:
            return chosen, True
        if spent + boxes[j] > budget:  # a region this wide is texture, not a target
            continue
        chosen.append(j + 1)
        spent += boxes[j]
    return chosen, len(chosen) >= limit


def _most_prominent(top_excess: np.ndarray, boxes: list[int], limit: int, budget: float) -> list[int]:
    """The regions (labels) a capped frame examines: by ``top_excess``, largest first, ties in
    label order, as a stable sort of every region gives them. Noise holds a thousand regions
    and 32 are examined, so the order is taken first only among the few most prominent (a
    partition, every tie at its edge included): sorting them all was a tenth of the frame."""
    n = top_excess.size
    if limit <= 0 or not n:
        return []
    head = min(n, 4 * limit)
    key = -top_excess
    if head < n:
        edge = np.partition(key, head - 1)[head - 1]
        first = np.flatnonzero(key <= edge)  # ascending labels: the stable sort keeps their order
        chosen, done = _pick(first[np.argsort(key[first], kind="stable")].tolist(), boxes, limit, budget)
        if done or first.size == n:
            return chosen
    return _pick(np.argsort(key, kind="stable").tolist(), boxes, limit, budget)[0]


_MOSAIC_MAX_ROWS = 64  # windows up to this tall are labelled together, side by side
_FLAT_SAMPLE_ROWS = 64  # flat_answer's first look: every 64th row (8 rows of a 512-row frame)


def _components(windows: list[tuple[int, int, np.ndarray]], structure: np.ndarray,
                min_area: int) -> list[tuple[int, int, int, tuple[slice, slice], np.ndarray]]:
    """Connected components of at least ``min_area`` pixels in each window's mask: (window y0,
    x0, area, slice within the window, own mask), window by window and in raster order within
    each, as labelling each window alone gives them. Small windows are laid side by side, a
    blank column apart, and labelled in one call: on noise, 32 separate calls of a few
    microseconds' work each cost more in scipy's per-call overhead than the frame's whole
    background estimate."""
    out: list[tuple[int, int, int, int, int, tuple[slice, slice], np.ndarray]] = []  # window, label first

    def add(labels: np.ndarray, n: int, members: list[int], offsets: np.ndarray) -> None:
        if not n:
            return
        areas = np.bincount(labels.ravel(), minlength=n + 1)
        keep = np.flatnonzero(areas[1:] >= min_area)
        if not keep.size:
            return
        objects = _ndimage().find_objects(labels)
        starts = np.fromiter((objects[i][1].start for i in keep.tolist()), np.intp, keep.size)
        owners = (np.searchsorted(offsets, starts, side="right") - 1).tolist()
        for i, j in zip(keep.tolist(), owners, strict=True):
            sl, off = objects[i], int(offsets[j])
            y0, x0, _ = windows[members[j]]
            out.append((members[j], i, y0, x0, int(areas[i + 1]),
                        (sl[0], slice(sl[1].start - off, sl[1].stop - off)), labels[sl] == i + 1))

    small = [i for i, (_, _, m) in enumerate(windows) if m.shape[0] <= _MOSAIC_MAX_ROWS and m.size]
    zero = np.zeros(1, np.intp)
    for i, (_, _, m) in enumerate(windows):
        if m.size and m.shape[0] > _MOSAIC_MAX_ROWS:
            labels, n = _ndimage().label(m, structure=structure)
            add(labels, n, [i], zero)
    if small:
        offsets = np.cumsum([0] + [windows[i][2].shape[1] + 1 for i in small])
        canvas = np.zeros((max(windows[i][2].shape[0] for i in small), int(offsets[-1])), bool)
        for i, off in zip(small, offsets[:-1].tolist(), strict=False):
            m = windows[i][2]
            canvas[:m.shape[0], off:off + m.shape[1]] = m
        labels, n = _ndimage().label(canvas, structure=structure)
        add(labels, n, small, offsets)
    out.sort(key=lambda c: (c[0], c[1]))
    return [(y0, x0, area, sl, own) for _, _, y0, x0, area, sl, own in out]


@dataclass
class HotSpotDetector:
    model: RadiometricModel
    threshold_k: float = DETECTION_THRESHOLD_K
    min_sigma: float = 4.0
    min_area: int = 4
    max_size: int = 48
    ring_px: int = 6
    bad_pixel_map: np.ndarray | None = None
    max_targets: int = 64
    # The worst case is bounded: a frame where more than this share of the coarse cells stands
    # above the background holds noise or texture, not targets (the simulator's busiest scenes
    # stay under 3%); and at most this many candidate regions are examined at full resolution,
    # the most prominent first, per 640x512 frame (in proportion to the frame's area, at least
    # 8: a region costs about the same whatever the frame, and the writer's work a frame is in
    # proportion to its area, so the detector keeps pace with it on every scene). Either cap,
    # when it bites, is named in the sidecar.
    max_candidate_fraction: float = 0.25
    max_regions: int = 32
    max_examined_share: float = 0.1  # of the frame's area, in the candidate regions' boxes
    _tracks: list[tuple[str, list[int]]] = field(default_factory=list, repr=False)
    _bad_coords: np.ndarray | None = field(default=None, repr=False)
    # the map _bad_coords was taken from: a map assigned later is read again; one changed in
    # place is not (assign a new array)
    _bad_source: np.ndarray | None = field(default=None, repr=False)
    _next_id: int = field(default=1, repr=False)

    _F = 4  # the coarse grid: 4x4 pixels a cell (the strided sums in _cells assume 4)
    # Built once: scipy builds the structure again on every call otherwise, a frame labels ~20 regions
    _EIGHT: Any = field(default_factory=lambda: np.ones((3, 3), bool), repr=False)
    _FOUR: Any = field(default_factory=lambda: np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool), repr=False)

    def _cells(self, temps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Quarter-resolution (cell mean, cell maximum) of ``temps``, and ``temps`` edge-padded to
        whole cells (itself where it already is)."""
        f = self._F
        h, w = temps.shape
        ph, pw = -(-h // f) * f, -(-w // f) * f
        padded = temps if (ph, pw) == (h, w) else np.pad(temps, ((0, ph - h), (0, pw - w)), mode="edge")
        if padded.dtype == np.uint16 and detector_kernels.available():  # counts: one compiled pass
            mean, cmax = detector_kernels.cell_mean_max(padded, f)
        else:
            # Strided element-wise ops (numpy's reductions over a 4-long inner axis are 10x slower),
            # rows first: those ops run on whole contiguous rows and leave a quarter for the columns.
            rows = [padded[i::f] for i in range(f)]
            rsum = rows[0].astype(np.float32)  # counts or temperatures: summed in float32 either way
            rsum += rows[1]
            rsum += rows[2]
            rsum += rows[3]
            rmx = np.maximum(np.maximum(rows[0], rows[1]), np.maximum(rows[2], rows[3]))
            mean = (rsum[:, 0::f] + rsum[:, 1::f] + rsum[:, 2::f] + rsum[:, 3::f]) * np.float32(1.0 / (f * f))
            cmax = np.maximum(np.maximum(rmx[:, 0::f], rmx[:, 1::f]), np.maximum(rmx[:, 2::f], rmx[:, 3::f]))
        return mean, cmax, padded

    def _opening(self, mean: np.ndarray, counts: bool = False) -> np.ndarray:
        """The background: a grey opening (min then max filter) of the cell means wider than any
        target (``max_size``). It removes warm objects but keeps edges such as the horizon, where
        a smoothed or block background would leave a band of false targets. On ``counts`` (no
        NaN) one compiled pass where numba is installed, the same numbers."""
        k = self.max_size // self._F + 1
        if counts and mean.dtype == np.float32 and detector_kernels.available():
            return detector_kernels.opening(mean, k)
        return sliding_extreme(sliding_extreme(mean, k, np.minimum), k, np.maximum)

    def _too_flat(self, mean: np.ndarray, cmax: np.ndarray, affine: tuple[np.float32, np.float32] | None) -> bool:
        """Whether no cell can stand ``threshold_k`` above the background, whatever the opening
        gives: the opening is never below the coarsest mean, nor a cell above the warmest, so a
        frame whose warmest cell is within ``threshold_k`` of its coldest mean has no candidate.
        Exact, rounding included: the same float32 operations, each monotonic, on the extremes
        (``_affine32`` on counts, as the cells get it). A uniform or low-contrast view (a wall,
        fog, the sea, a lens cap) then costs the cell grid alone: half of a flat 640x512 frame."""
        if not mean.size:
            return False
        return self._within_threshold(mean.min(), cmax.max(), affine)

    def _grid_excess(self, opened: np.ndarray, mean: np.ndarray, cmax: np.ndarray,
                     affine: tuple[np.float32, np.float32] | None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """The coarse grids in temperatures (on counts, converted here: only the grid and the
        windows looked at ever are), each cell maximum's excess over the background, the cells
        standing ``threshold_k`` above it, and how many: (opened, mean, cmax, excess, cells,
        count). One compiled pass on counts where numba is installed, the same float32 steps."""
        if affine is not None and cmax.dtype == np.uint16 and detector_kernels.available():
            return detector_kernels.grid_excess(opened, mean, cmax, *affine, self.threshold_k)
        if affine is not None:
            opened, mean, cmax = (_affine32(a, *affine) for a in (opened, mean, cmax))
        excess = cmax - opened
        cells = excess >= self.threshold_k
        return opened, mean, cmax, excess, cells, int(np.count_nonzero(cells))

    def _within_threshold(self, lo: np.generic, hi: np.generic, affine: tuple[np.float32, np.float32] | None) -> bool:
        """Whether ``hi`` (a numpy scalar, counts or temperatures) stands less than ``threshold_k``
        above ``lo``, through ``_affine32``'s float32 steps on numpy scalars (arrays of one,
        as before, cost the recording process 10 us a frame for this)."""
        if affine is not None:
            scale, offset = affine
            lo, hi = np.float32(lo) * scale + offset, np.float32(hi) * scale + offset
        return bool(hi - lo < self.threshold_k)  # type: ignore[operator]

    def flat_answer(self, raw: np.ndarray) -> tuple[list[Detection], dict[str, Any]] | None:
        """``detect(raw)``'s answer for a frame of counts too flat to hold any candidate, decided
        from its coldest and warmest count alone; ``None`` where it may hold one, or where the
        model is not linear in counts or the frame has bad pixels to mend (then only ``detect``
        knows). The tracks are left as they are: the caller that answers a frame this way must
        ``forget_tracks`` on the detector that sees the next frame, as ``detect`` would have.

        Why: the recorder's detector runs in a child process, and handing it a frame (a copy into
        shared memory, a message each way, two threads woken) cost a file source of a flat view
        more than the detector's answer does. Exact, and never a frame ``detect`` would answer
        otherwise: the coldest count is at most the coldest cell's mean and the warmest is the
        warmest cell's maximum, so this span is never narrower than ``_too_flat``'s, through the
        same monotonic float32 steps. A sparse sample of rows is looked at first: a frame whose
        sample already spans the threshold (every ordinary scene) costs a few microseconds."""
        if raw.dtype != np.uint16 or raw.ndim != 2 or not raw.size:
            return None
        affine = _counts_affine(self.model)
        if affine is None:
            return None
        sample = raw[::_FLAT_SAMPLE_ROWS]
        if not self._within_threshold(sample.min(), sample.max(), affine):
            return None
        # a frame with bad pixels to mend is detect's to answer (on temperatures, mended)
        if self._has_bad_pixels(raw.shape) or \
                not self._within_threshold(raw.min(), raw.max(), affine):
            return None
        return [], self._analysis([], [], None)

    def prime(self) -> None:
        """Pay the detector's first-call costs (scipy's lazy imports, numpy's first dispatch of
        each operation: about 0.2 s) on a copy and a small frame with one target, so a live
        camera's first frames are not skipped behind them. This detector's tracks are untouched."""
        frame = np.full((64, 64), 1000, np.uint16)
        frame[20:28, 30:38] = 3000
        # a model whose counts this frame does not suit: the first real frame pays instead
        with contextlib.suppress(Exception):
            copy.deepcopy(self).detect(frame)

    def forget_tracks(self) -> None:
        """What a frame with no target does to the tracks (``flat_answer``'s other half): the
        same tracking step, with nothing found."""
        self._track([])

    def background(self, temps: np.ndarray) -> np.ndarray:
        """The local background (C) at full resolution."""
        opened = self._opening(self._cells(temps)[0])
        h, w = temps.shape
        return np.repeat(np.repeat(opened, self._F, axis=0), self._F, axis=1)[:h, :w]

    def _bad_pixels(self) -> np.ndarray:
        """The map's bad pixels, (y, x) a row: taken once for each map assigned, not on every
        frame (reading a 640x512 map was 10-20 us, twice a frame)."""
        if self._bad_source is not self.bad_pixel_map or self._bad_coords is None:
            self._bad_coords = np.argwhere(self.bad_pixel_map) if self.bad_pixel_map is not None \
                else np.zeros((0, 2), np.intp)
            self._bad_source = self.bad_pixel_map
        return self._bad_coords

    def _has_bad_pixels(self, shape: tuple[int, ...]) -> bool:
        return self.bad_pixel_map is not None and self.bad_pixel_map.shape == shape and len(self._bad_pixels()) > 0

    def _fix_bad_pixels(self, temps: np.ndarray) -> np.ndarray:
        if not self._has_bad_pixels(temps.shape):
            return temps
        assert self.bad_pixel_map is not None
        coords = self._bad_pixels()
        if temps.dtype == np.float32 and self.bad_pixel_map.dtype == np.bool_ and detector_kernels.available():
            return detector_kernels.mend_bad_pixels(temps, self.bad_pixel_map, coords)
        out = temps.copy()
        for y, x in coords:  # dead and hot pixels would read as 1-px targets
            win = temps[max(0, y - 1):y + 2, max(0, x - 1):x + 2]
            good = win[~self.bad_pixel_map[max(0, y - 1):y + 2, max(0, x - 1):x + 2]]
            out[y, x] = np.median(good) if good.size else out[y, x]
        return out

    def _standing_out(self, stats: _RegionStats, examine: list[int],
                      local_mean: np.ndarray) -> list[tuple[int, int, int, int]]:
        """The boxes (in cells: y0, y1, x0, x1) of the regions of ``examine`` (labels) whose warmest
        cell stands out from the local mean at the box's centre. The others are texture, dropped
        here at quarter resolution before any full-resolution work. All the regions at once:
        one at a time, 32 regions of a noisy frame cost 30-45 us of Python."""
        if not examine:
            return []
        i = np.asarray(examine, np.intp) - 1
        boxes = np.stack([stats.y0[i], stats.y1[i], stats.x0[i], stats.x1[i]], axis=1)
        cy = np.minimum((boxes[:, 0] + boxes[:, 1]) // 2, local_mean.shape[0] - 1)
        cx = np.minimum((boxes[:, 2] + boxes[:, 3]) // 2, local_mean.shape[1] - 1)
        # "not below" rather than "at or above": a NaN (a temperature path) is kept, as before
        stands = ~(stats.top_cmax[i] - local_mean[cy, cx] < 0.8 * self.threshold_k)
        return [(a, b, c, d) for a, b, c, d in boxes[stands].tolist()]

    def _window_components(self, src: np.ndarray, padded_src: np.ndarray, opened: np.ndarray,
                           boxes: list[tuple[int, int, int, int]], affine: tuple[np.float32, np.float32] | None,
                           celsius: Any) -> list[tuple[int, int, int, tuple[slice, slice], np.ndarray]]:
        """The connected components (4-connected, at least ``min_area`` pixels) of the pixels
        standing ``threshold_k`` above the background in each region's box: one compiled pass
        over every box where numba is installed (on noise, 32 boxes a frame made their masks
        and labels in a few dozen numpy and scipy calls), else those calls. The same answers."""
        f = self._F
        h, w = src.shape
        if boxes and detector_kernels.available():
            scale, offset = affine if affine is not None else (np.float32(1.0), np.float32(0.0))
            return detector_kernels.window_components(src, opened, np.array(boxes), f, scale, offset,
                                                      self.threshold_k, self.min_area)
        windows: list[tuple[int, int, np.ndarray]] = []  # (y0, x0, candidate mask) per box
        for cy0, cy1, cx0, cx1 in boxes:
            ry0, ry1 = cy0 * f, min(h, cy1 * f)
            rx0, rx1 = cx0 * f, min(w, cx1 * f)
            # The region's box is whole cells: its background broadcasts, cell by cell
            block = opened[cy0:cy1, cx0:cx1]
            ny, nx = block.shape
            cells_px = celsius(padded_src[ry0:ry0 + ny * f, rx0:rx0 + nx * f]).reshape(ny, f, nx, f)
            cand = ((cells_px - block[:, None, :, None]) >= self.threshold_k).reshape(ny * f, nx * f)
            windows.append((ry0, rx0, cand[:ry1 - ry0, :rx1 - rx0]))
        return _components(windows, self._FOUR, self.min_area)

    def detect(self, raw: np.ndarray) -> tuple[list[Detection], dict[str, Any]]:
        """Targets in one frame, and the sidecar's ``thermal_analysis`` block.

        Coarse to fine: cells whose maximum stands ``threshold_k`` above the background are found
        at quarter resolution, and only those regions are labelled at full resolution, so a frame
        with few warm spots costs little more than the background estimate."""
        f = self._F
        h, w = raw.shape
        affine = _counts_affine(self.model) if not self._has_bad_pixels(raw.shape) else None
        src = raw if affine is not None else self._fix_bad_pixels(_celsius32(self.model, raw))
        cell_mean, cmax, padded_src = self._cells(src)
        dets: list[Detection] = []
        per_target: list[dict[str, Any]] = []
        if self._too_flat(cell_mean, cmax, affine):
            return self._answer(dets, per_target, None)
        opened, cell_mean, cmax, excess_cells, cells, hits = self._grid_excess(
            self._opening(cell_mean, counts=cmax.dtype == np.uint16), cell_mean, cmax, affine)
        if affine is not None:  # on counts; only the grid and the windows looked at are converted
            def celsius(a: np.ndarray) -> np.ndarray:
                return _affine32(a, *affine)
        else:
            def celsius(a: np.ndarray) -> np.ndarray:
                return a
        capped: dict[str, Any] | None = None
        share = hits / cells.size
        if share > self.max_candidate_fraction:
            capped = {"rule": "candidate_cell_fraction", "value": round(share, 4), "limit": self.max_candidate_fraction,
                      "why": "more of the frame stands above its background than targets can: noise or texture"}
            cells = np.zeros_like(cells)
        if cells.any():
            def bg(y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
                """The background over a full-resolution window, from the coarse grid (only
                where there are candidates: a whole-frame copy cost more than the rest)."""
                cy0, cx0 = y0 // f, x0 // f
                block = opened[cy0:-(-y1 // f), cx0:-(-x1 // f)]
                full = np.repeat(np.repeat(block, f, axis=0), f, axis=1)
                return full[y0 - cy0 * f:y1 - cy0 * f, x0 - cx0 * f:x1 - cx0 * f]

            # the mean around each cell, as wide as the opening: only a frame with candidates needs it
            local_mean = _local_mean(cell_mean, 2 * (self.max_size // f + 1) - 1)
            n_regions, stats = _regions(cells, excess_cells, cmax, self._EIGHT)
            examine: list[int] = list(range(1, n_regions + 1))
            budget = self.max_examined_share * cells.size  # in coarse cells
            boxes = stats.areas()
            region_limit = max(min(8, self.max_regions), round(self.max_regions * h * w / (640 * 512)))
            if n_regions > region_limit or sum(boxes) > budget:
                # the most prominent regions first, until the count or the area budget is spent
                chosen = _most_prominent(stats.top_excess, boxes, region_limit, budget)
                capped = {"rule": "max_regions", "value": int(n_regions), "examined": len(chosen),
                          "limit": region_limit, "area_budget": self.max_examined_share,
                          "why": "only the most prominent candidate regions were examined"}
                examine = sorted(chosen)
            kept = self._standing_out(stats, examine, local_mean)
            found = []
            for y0, x0, area, sl, own in self._window_components(src, padded_src, opened, kept, affine, celsius):
                found.append((area, sl[0].start + y0, sl[0].stop + y0, sl[1].start + x0, sl[1].stop + x0, own))
            found.sort(key=lambda c: -c[0])
            if len(found) > 4 * self.max_targets:  # the largest first; the rest not examined
                capped = capped or {"rule": "max_candidates", "value": len(found), "limit": 4 * self.max_targets,
                                    "why": "only the largest candidates were examined"}
                found = found[:4 * self.max_targets]
            for _area, y0, y1, x0, x1, own in found:
                if len(dets) >= self.max_targets:
                    break
                # Cheapest test: the peak against the local mean around it (texture bumps fail here).
                local = local_mean[min((y0 + y1) // (2 * f), local_mean.shape[0] - 1),
                                   min((x0 + x1) // (2 * f), local_mean.shape[1] - 1)]
                peak = float(celsius(src[y0:y1, x0:x1])[own].max())
                if peak - local < 0.8 * self.threshold_k:
                    continue
                r = self.ring_px
                Y0, Y1, X0, X1 = max(0, y0 - r), min(h, y1 + r), max(0, x0 - r), min(w, x1 + r)
                crop = celsius(src[Y0:Y1, X0:X1])
                tmask = np.zeros(crop.shape, bool)
                tmask[y0 - Y0:y1 - Y0, x0 - X0:x1 - X0] = own
                # Next, the rectangular ring outside the component's box: a target stands above
                # the ring around it, not just above the opening's floor; texture and slopes do not.
                rect = np.ones(crop.shape, bool)
                rect[max(0, y0 - 1 - Y0):y1 + 1 - Y0, max(0, x0 - 1 - X0):x1 + 1 - X0] = False
                if not rect.any():
                    continue
                ring = crop[rect]
                excess = peak - _median(ring)
                if excess < self.threshold_k or excess < self.min_sigma * (float(np.std(ring)) + 1e-3):
                    continue
                warm = (crop - bg(Y0, Y1, X0, X1)) >= self.threshold_k  # this and any neighbouring target
                bmask = ~_dilated(warm | tmask, 2)
                if not bmask.any():
                    continue
                m = contrast_metrics(crop, tmask, bmask)
                ys, xs = np.nonzero(tmask)
                dets.append(Detection(
                    target_id="", bbox=[int(x0), int(y0), int(x1 - 1), int(y1 - 1)],
                    centroid=[round(float(xs.mean() + X0), 2), round(float(ys.mean() + Y0), 2)],
                    max_temp_c=m["max_target_temp_c"], mean_temp_c=m["mean_target_temp_c"],
                    confidence=float(1.0 - math.exp(-excess / max(self.threshold_k, 1e-6))), metrics=m))
                per_target.append(m)
        return self._answer(dets, per_target, capped)

    def _answer(self, dets: list[Detection], per_target: list[dict[str, Any]],
                capped: dict[str, Any] | None) -> tuple[list[Detection], dict[str, Any]]:
        self._track(dets)
        return dets, self._analysis(dets, per_target, capped)

    @staticmethod
    def _analysis(dets: list[Detection], per_target: list[dict[str, Any]],
                  capped: dict[str, Any] | None) -> dict[str, Any]:
        conf = max((d.confidence for d in dets), default=None)
        analysis = frame_analysis(per_target, source="detector", confidence=round(conf, 3) if conf else None)
        if capped is not None:
            analysis["detection_capped"] = capped
        return analysis

    def _track(self, dets: list[Detection]) -> None:
        """Keep a target's id while its box overlaps the one it had in the previous frame."""
        free = list(self._tracks)
        new_tracks = []
        for d in sorted(dets, key=lambda d: -(d.bbox[2] - d.bbox[0] + 1) * (d.bbox[3] - d.bbox[1] + 1)):
            best = max(free, key=lambda t: iou(t[1], d.bbox), default=None)
            if best is not None and iou(best[1], d.bbox) > 0.1:
                d.target_id = best[0]
                free.remove(best)
            else:
                d.target_id = f"HS{self._next_id:05d}"
                self._next_id += 1
            new_tracks.append((d.target_id, d.bbox))
        self._tracks = new_tracks


@dataclass
class EventBuilder:
    """Session events from per-frame sidecars: ``thermal_crossover`` (grade below 0.3 for at
    least ``min_crossover_s``) and ``slew_to_cue`` (cue received until lock)."""

    min_crossover_s: float = 1.0
    events: list[dict[str, Any]] = field(default_factory=list)
    _low_start: int | None = None
    _low_last: int | None = None
    _low_min: float = 1.0
    _cue_start: int | None = None
    _cue_detail: dict[str, Any] = field(default_factory=dict)
    _last_t: int | None = None

    def add(self, t_ns: int, sidecar: dict[str, Any]) -> None:
        grade = graded_contrast(sidecar.get("thermal_analysis"))
        if grade is not None and grade < CROSSOVER_GRADE:
            if self._low_start is None:
                self._low_start, self._low_min = t_ns, grade
            self._low_last = t_ns
            self._low_min = min(self._low_min, grade)
        elif grade is not None:
            self._close_low()
        stc = sidecar.get("slew_to_cue") or {}
        state = stc.get("state")
        active = state in ("slew", "search") if state else bool(stc.get("slew_to_cue_active"))
        if active and self._cue_start is None:
            self._cue_start = t_ns
            self._cue_detail = {k: stc.get(k) for k in ("radar_azimuth_deg", "radar_elevation_deg", "radar_range_m")}
        elif not active and self._cue_start is not None:
            self._cue_detail["ended_in"] = state or "inactive"
            self.events.append({"kind": "slew_to_cue", "start_ns": self._cue_start, "end_ns": t_ns,
                                "detail": self._cue_detail})
            self._cue_start = None
        self._last_t = t_ns

    def _close_low(self) -> None:
        if self._low_start is not None and self._low_last is not None \
                and (self._low_last - self._low_start) / 1e9 >= self.min_crossover_s:
            self.events.append({"kind": "thermal_crossover", "start_ns": self._low_start, "end_ns": self._low_last,
                                "detail": {"min_grade": round(self._low_min, 4)}})
        self._low_start = self._low_last = None

    def finish(self) -> list[dict[str, Any]]:
        self._close_low()
        if self._cue_start is not None and self._last_t is not None:
            self.events.append({"kind": "slew_to_cue", "start_ns": self._cue_start, "end_ns": self._last_t,
                                "detail": {**self._cue_detail, "ended_in": "end of session"}})
            self._cue_start = None
        return sorted(self.events, key=lambda e: e["start_ns"])
