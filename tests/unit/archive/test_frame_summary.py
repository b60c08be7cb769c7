"""The frame summary gives the whole frame's statistics only where they are exact: a model that
is not monotonic over the session's counts (or gives no temperature there) and, for the mean, one
that is not affine there, are refused rather than approximated."""

from __future__ import annotations

import numpy as np
import pytest

from thermcap.archive.frame_summary import SummaryBuilder, band_crc32, load_summary


@pytest.fixture
def frames():
    rng = np.random.default_rng(4)
    return [rng.integers(1000, 9000, (70, 33), dtype=np.uint16) for _ in range(9)]


def _summary(frames):
    b = SummaryBuilder(4)  # fewer than fed: the arrays grow
    for f in frames:
        b.add(f)
    return load_summary(b.finish().to_bytes())


def test_statistics_and_bands_round_trip(frames):
    s = _summary(frames)
    assert s.frames == 9 and (s.height, s.width) == (70, 33)
    assert list(s.max) == [f.max() for f in frames] and list(s.min) == [f.min() for f in frames]
    assert list(s.band_crc32[3]) == list(band_crc32(frames[3]))
    assert s.rows_intact(3, 64, frames[3][64:]) and not s.rows_intact(3, 64, frames[4][64:])
    assert not s.checkable(32, 32) and s.checkable(0, 64) and s.checkable(64, 6)


def test_exact_where_the_model_allows(frames):
    s = _summary(frames)
    idx = np.arange(9)

    def linear(c):
        return c * 0.04 - 273.15

    assert s.celsius("max", idx, linear) == pytest.approx([float(np.float32(linear(f.max()))) for f in frames],
                                                          abs=1e-4)
    assert s.celsius("mean", idx, linear) == pytest.approx([np.float32(linear(f.astype(float))).mean()
                                                            for f in frames], abs=2e-4)

    def planck(c):  # monotonic, not affine
        return 1400.0 / np.log(1e5 / c + 1.0) - 273.15

    assert s.celsius("max", idx, planck) == pytest.approx([float(np.float32(planck(float(f.max())))) for f in frames],
                                                          abs=1e-3)
    assert s.celsius("mean", idx, planck) is None
    assert s.celsius("max", idx, lambda c: np.cos(c / 500.0)) is None  # not monotonic
    assert s.celsius("min", idx, lambda c: np.where(c > 5000, np.nan, c * 1.0)) is None  # no temperature there


def test_band_checksums_are_plain_crc32_of_each_band_s_little_endian_bytes():
    import zlib

    rng = np.random.default_rng(9)
    for pixels in (rng.integers(0, 65536, (130, 33), dtype=np.uint16),
                   rng.integers(0, 65536, (130, 66), dtype=np.uint16)[:, ::2],  # not contiguous
                   rng.integers(0, 65536, (130, 33), dtype=np.uint16).astype(">u2")):  # big-endian input
        le = np.ascontiguousarray(pixels, dtype="<u2")
        want = [zlib.crc32(le[y:y + 64].tobytes()) for y in range(0, 130, 64)]
        assert band_crc32(pixels).tolist() == want
