"""``percentiles`` must give exactly what ``np.percentile`` gives, for every kind of image."""

from __future__ import annotations

import numpy as np
import pytest

from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exports.percentiles import percentiles
from thermcap.recorder.exports.render import celsius, frame_range

QS = [(0.5, 99.5), (0, 100), (50,), (1, 2.5, 25, 75, 97.5, 99.9), (5, 25, 50, 75, 95)]


def _images() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    sim = SimSource(width=640, height=512, frames=1, paced=False)
    frame = next(iter(sim.frames()))
    return {
        "simulated frame in degC": celsius(frame.pixels, sim.model),
        "wide normal": (rng.standard_normal((300, 400)) * 1e3).astype(np.float32),
        "tiny spread": (20 + rng.standard_normal((256, 320)) * 1e-4).astype(np.float32),
        "few values, many repeats": rng.integers(-5, 5, (256, 320)).astype(np.float32),
        "one value": np.full((512, 640), 21.5, np.float32),
        "infinities at both ends": np.concatenate([rng.random(50_000), [np.inf, -np.inf] * 300]).astype(np.float32),
        "signed zeros": np.array([-0.0, 0.0, -1.0, 1.0] * 10_000, np.float32),
        "subnormals and extremes": np.concatenate([rng.random(40_000) * 1e-40, [3.4e38, -3.4e38, 1e-45]])
        .astype(np.float32),
        "odd size": rng.random(20_011).astype(np.float32),
    }


@pytest.mark.parametrize("name", list(_images()))
def test_equal_to_numpy_bit_for_bit(name):
    values = _images()[name]
    with np.errstate(invalid="ignore"):  # inf - inf, as numpy itself meets it
        for qs in QS:
            ours = percentiles(values, qs)
            theirs = [float(v) for v in np.percentile(values, qs)]
            assert np.array_equal(ours, theirs, equal_nan=True), (name, qs, ours, theirs)


@pytest.mark.parametrize("values", [
    np.array([np.nan, 1.0, 2.0] * 10_000, np.float32),  # NaN: numpy's answer (NaN), through numpy
    np.arange(100, dtype=np.float32),  # small: a plain partition
    np.arange(40_000, dtype=np.float64),  # not float32
    np.arange(40_000, dtype=np.uint16),  # counts
], ids=["nan", "small", "float64", "uint16"])
def test_what_it_does_not_rank_itself_goes_to_numpy(values):
    assert np.array_equal(percentiles(values, (0.5, 50, 99.5)), np.percentile(values, (0.5, 50, 99.5)),
                          equal_nan=True)


def test_a_percentile_outside_0_to_100_is_refused():
    with pytest.raises(ValueError, match=r"0\.\.100"):
        percentiles(np.zeros(40_000, np.float32), (101,))


def test_the_colour_scale_uses_it():
    values = _images()["simulated frame in degC"]
    rng = frame_range(values)
    assert (rng.lo, rng.hi) == tuple(float(v) for v in np.percentile(values, (0.5, 99.5)))
