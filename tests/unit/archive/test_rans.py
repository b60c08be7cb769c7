"""tpred v4's entropy coder (``archive.codecs.tpred.rans``) and key-frame coder (``archive.codecs.tpred.key``):
every int32 value round-trips, the coder sits at its table's entropy, and damage is refused
with the reason instead of decoding to other numbers."""

from __future__ import annotations

import glob

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import SAMPLES
from thermcap.archive.codecs.tpred import key as tpred_key
from thermcap.archive.codecs.tpred import rans


@pytest.mark.parametrize("values", [
    np.array([0], np.int32),
    np.array([-2**31, 2**31 - 1, 0, 1, -1, 15, 16, -16, -17, 31, 32, 65535, -65535], np.int32),
    np.random.default_rng(0).integers(-2**31, 2**31 - 1, 2000).astype(np.int32),
    np.clip(np.random.default_rng(1).standard_cauchy(50_000) * 4, -2**31, 2**31 - 1).astype(np.int32),
    np.full(10_000, 7, np.int16),
])
def test_values_round_trip(values):
    assert np.array_equal(rans.decode(rans.encode(values), values.size), values.astype(np.int32))


def _pinned_streams() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    return [np.array([5], np.int32), np.array([5, -300], np.int32),
            np.array([-2**31, 2**31 - 1, 0, 1, -1, 15, 16, -16, -17, 31, 32, 65535, -65535], np.int32),
            np.rint(rng.normal(0, 1.45, 100_001)).astype(np.int32),
            np.clip(rng.standard_cauchy(50_000) * 40, -2**31, 2**31 - 1).astype(np.int32)]


def test_the_encoder_writes_the_bytes_it_always_wrote():
    """The same values give the same stream, byte for byte, whatever the encoder's loop looks
    like inside: an archive re-encoded stays identical (and dedupes). One value, two, an odd and
    an even count, every token's extra bits. Pinned from the encoder of 2026-12-06, before its
    loop went a pair of values a turn."""
    import hashlib

    pinned = ["c1222de4e169250092f8", "91ce86b889a17b3ae292", "0799a42def7f420b2f82", "eb955cad8e21567e4ee1",
              "eeaaa8be7e10f0ce7573"]
    assert [hashlib.sha256(rans.encode(v)).hexdigest()[:20] for v in _pinned_streams()] == pinned


@settings(max_examples=300, deadline=None)
@given(st.integers(-2**31, 2**31 - 1))
def test_a_values_token_follows_the_hybrid_integer_rule(v):
    """The rule in ``archive.codecs.tpred.rans``'s docstring, from Python's own bit length: the coder finds
    ``k`` with a loop it may shorten, and a wrong ``k`` writes other bytes for the same value."""
    u = 2 * v if v >= 0 else -2 * v - 1
    if u < 32:
        expected = (u, 0, 0)
    else:
        k = u.bit_length() - 1
        expected = (32 + 2 * (k - 5) + ((u >> (k - 1)) & 1), k - 1, u & ((1 << (k - 1)) - 1))
    assert tuple(int(x) for x in rans.token(np.int64(v))) == expected


def test_an_empty_stream_is_empty():
    assert rans.encode(np.empty(0, np.int32)) == b""
    assert rans.decode(b"", 0).size == 0
    with pytest.raises(rans.RansError, match="empty stream holds"):
        rans.decode(b"\x01", 0)


def test_the_coder_reaches_the_entropy_of_its_table():
    """Rounded Gaussian noise of 1.45 counts (the simulator's NETD): within 0.3% of the
    zeroth-order entropy, the table included."""
    v = np.rint(np.random.default_rng(2).normal(0, 1.45, 200_000)).astype(np.int32)
    _, counts = np.unique(v, return_counts=True)
    p = counts / v.size
    entropy_bytes = float(-(counts * np.log2(p)).sum()) / 8
    assert len(rans.encode(v)) < 1.003 * entropy_bytes


def test_damage_is_refused_with_the_reason():
    v = np.rint(np.random.default_rng(3).normal(0, 3, 5000)).astype(np.int32)
    good = rans.encode(v)
    with pytest.raises(rans.RansError, match="ends before its values"):
        rans.decode(good[:-4], v.size)
    with pytest.raises(rans.RansError, match="left after"):
        rans.decode(good + b"\x00", v.size)
    with pytest.raises(rans.RansError, match="sum to"):
        rans.decode(good[:1] + bytes([good[1] ^ 0x01]) + good[2:], v.size)
    with pytest.raises(rans.RansError, match="tokens"):
        rans.decode(b"\x00" + good[1:], v.size)
    refused = 0
    for i in range(len(good) // 2, len(good), max(1, len(good) // 40)):
        bad = bytearray(good)
        bad[i] ^= 0x5A
        try:
            out = rans.decode(bytes(bad), v.size)
        except rans.RansError:
            refused += 1
        else:  # what still decodes must at least not claim to be the same numbers unnoticed
            assert not np.array_equal(out, v) or bytes(bad) == good
    assert refused >= 15


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2), (33, 17)])
def test_key_frames_round_trip_at_any_size_and_the_extremes(shape):
    rng = np.random.default_rng(4)
    for f in (rng.integers(0, 65536, shape), np.zeros(shape), np.full(shape, 65535)):
        f = f.astype(np.uint16)
        assert np.array_equal(tpred_key.decode_key(tpred_key.encode_key(f), shape), f)


def test_key_frames_beat_vertical_differences_on_the_simulator_and_real_frames():
    import imagecodecs

    from thermcap.recorder.capture.sources.sim import SimSource

    frames = [next(iter(SimSource(width=640, height=512, frames=1, paced=False, seed=21,
                                  pixel_fpn_mk=15.0).frames())).pixels]
    bins = glob.glob(str(SAMPLES / "terraref" / "*_ir.bin"))
    if bins:
        frames.append(np.fromfile(bins[0], "<u2").reshape(480, 640))
    for f in frames:
        payload = tpred_key.encode_key(f)
        assert np.array_equal(tpred_key.decode_key(payload, f.shape), f)
        d = f.astype(np.int32)
        d[1:] -= f[:-1].astype(np.int32)
        assert len(payload) < 0.96 * len(imagecodecs.pcodec_encode(d, level=8))


def test_a_damaged_key_frame_is_refused():
    f = np.random.default_rng(5).integers(1000, 1100, (20, 30)).astype(np.uint16)
    good = tpred_key.encode_key(f)
    with pytest.raises(tpred_key.KeyFrameError, match="ends before context"):
        tpred_key.decode_key(good[:6], f.shape)
    with pytest.raises(tpred_key.KeyFrameError, match="follow the key frame"):
        tpred_key.decode_key(good + b"\x00", f.shape)
    with pytest.raises(tpred_key.KeyFrameError, match=r"hold .* values for"):
        tpred_key.decode_key(good, (20, 31))


def _runs_frame(shape=(128, 160), share=0.6):
    from thermcap.recorder.capture.sources.sim import SimSource

    return next(iter(SimSource(width=shape[1], height=shape[0], frames=1, paced=False, seed=9, netd_mk=400.0,
                               row_runs=share).frames())).pixels


@pytest.mark.parametrize("shape", [(1, 1), (1, 3), (3, 1), (2, 2), (33, 17)])
@pytest.mark.parametrize("rule", [0, 1, -1])
def test_version_7_key_frames_round_trip_under_each_rule(shape, rule):
    rng = np.random.default_rng(6)
    runs = np.repeat(rng.integers(0, 65536, (shape[0], (shape[1] + 2) // 3)), 3, axis=1)[:, :shape[1]]
    for f in (rng.integers(0, 65536, shape), np.zeros(shape), np.full(shape, 65535), runs):
        f = f.astype(np.uint16)
        payload = tpred_key.encode_key(f, rule=rule)
        assert payload[0] in tpred_key.RULES and (rule < 0 or payload[0] == rule)
        assert np.array_equal(tpred_key.decode_key(payload, shape, ruled=True), f)


def test_the_run_rule_is_chosen_where_rows_hold_runs_and_costs_nothing_elsewhere():
    """Issue 40: real FLIR CSQ frames repeat their left neighbour in 44-62 % of their pixels, and
    the four-neighbour predictor spent 5 bits a pixel there (JPEG XL e2 won by 5 %)."""
    from thermcap.recorder.capture.sources.sim import SimSource

    runs = _runs_frame()
    plain = tpred_key.encode_key(runs)
    chosen = tpred_key.encode_key(runs, rule=-1)
    assert chosen[0] == 1 and len(chosen) < 0.85 * len(plain)
    still = next(iter(SimSource(width=640, height=512, frames=1, paced=False, seed=21, pixel_fpn_mk=15.0)
                      .frames())).pixels  # 14 % of its pixels repeat their neighbour by chance
    assert len(tpred_key.encode_key(still, rule=-1)) <= 1.003 * len(tpred_key.encode_key(still))
    for f in (runs, still, _runs_frame(share=0.15)):  # whichever it picks costs at most 1 % over the other
        sizes = [len(tpred_key.encode_key(f, rule=r)) for r in tpred_key.RULES]
        assert len(tpred_key.encode_key(f, rule=-1)) <= (2 - tpred_key.RUN_MARGIN) * min(sizes)


@pytest.mark.parametrize("share", [0.0, 0.3, 0.6])
def test_each_rules_estimate_is_within_3_percent_of_its_streams(share):
    f = _runs_frame((256, 320), share)
    estimates = tpred_key.rule_costs(f, step=1)
    for rule, bits in zip(tpred_key.RULES, estimates, strict=True):
        actual = 8 * (len(tpred_key.encode_key(f, rule=rule)) - 1)
        assert abs(bits - actual) < 0.01 * actual, (rule, bits, actual)
    sampled = tpred_key.rule_costs(f)  # every other row of 256
    assert all(abs(a - b) < 0.02 * b for a, b in zip(sampled, estimates, strict=True))


def test_a_damaged_rule_is_refused():
    f = _runs_frame((20, 30))
    good = tpred_key.encode_key(f, rule=1)
    with pytest.raises(tpred_key.KeyFrameError, match="rule byte"):
        tpred_key.decode_key(b"", f.shape, ruled=True)
    with pytest.raises(tpred_key.KeyFrameError, match="rule is 2"):
        tpred_key.decode_key(b"\x02" + good[1:], f.shape, ruled=True)
    with pytest.raises(tpred_key.KeyFrameError):  # rule 0 reads five streams where six are: bytes left over
        tpred_key.decode_key(b"\x00" + good[1:], f.shape, ruled=True)
    with pytest.raises(ValueError, match="rules"):
        tpred_key.encode_key(f, rule=3)
