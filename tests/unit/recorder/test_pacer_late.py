"""Issue 64: "1573 frames late" of 2593 at 99.99% of the rate. A frame counted late when it was
released more than a period after its slot on the schedule, so one early stall left every frame
after it "late" while the source kept its rate. Late is now a frame that came more than half a
period later than the rate allows after the one before it: a stall, which normal jitter does not
cross, and a source that cannot keep its rate still counts every frame."""

from __future__ import annotations

import pytest

from thermcap.recorder.capture.sources import base


class _Clock:
    def __init__(self) -> None:
        self.now = 0

    def monotonic_ns(self) -> int:
        return self.now

    def sleep(self, s: float) -> None:
        self.now += round(s * 1e9)


@pytest.fixture
def clock(monkeypatch):
    c = _Clock()
    monkeypatch.setattr(base.time, "monotonic_ns", c.monotonic_ns)
    monkeypatch.setattr(base.time, "sleep", c.sleep)
    return c


def _run(clock: _Clock, work_ns: list[int], fps: float = 60.0) -> int:
    pacer = base.Pacer(fps)
    for i, work in enumerate(work_ns):
        clock.now += work  # producing frame i
        pacer.wait(i)
    return pacer.late


def test_one_stall_is_one_late_frame_not_every_frame_after_it(clock):
    period = round(1e9 / 60)
    work = [period // 2] * 100
    work[10] = 5 * period  # one stall of five periods, then the source keeps its rate again
    assert _run(clock, work) == 1


def test_jitter_is_not_lateness(clock):
    period = round(1e9 / 60)
    work = [period + (period // 3 if i % 2 else -period // 3) for i in range(200)]  # ±1/3 period each frame
    assert _run(clock, work) == 0


def test_a_source_at_half_its_rate_is_late_every_frame(clock):
    period = round(1e9 / 60)
    assert _run(clock, [2 * period] * 50) == 50  # every frame
