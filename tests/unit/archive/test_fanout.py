"""The frame stream read once and teed to every format writer (archive.fanout)."""

from __future__ import annotations

import pytest

from thermcap.archive.fanout import fan_out


def test_every_consumer_sees_every_item_once_in_order():
    reads = []

    def source():
        for i in range(500):
            reads.append(i)
            yield i

    results = fan_out(source(), [list, list, lambda it: sum(1 for _ in it)], depth=4)
    assert reads == list(range(500))  # the source is read once
    assert results[0] == list(range(500))
    assert results[1] == list(range(500))
    assert results[2] == 500


def test_a_failing_consumer_is_reported_and_does_not_stop_the_others():
    def fails(it):
        for i in it:
            if i == 10:
                raise ValueError("writer broke")
        return "never"

    results = fan_out(iter(range(1000)), [fails, list], depth=2)
    assert isinstance(results[0], ValueError)
    assert results[1] == list(range(1000))


def test_a_source_error_reaches_every_consumer():
    def source():
        yield 1
        raise OSError("segment unreadable")

    results = fan_out(source(), [list, list])
    assert all(isinstance(r, OSError) for r in results)


def test_memory_is_bounded_by_the_queue_depth():
    """A slow writer holds the producer back: at most its queue's depth is read ahead."""
    produced: list[int] = []
    ahead: list[int] = []

    def slow(it):
        import time

        time.sleep(0.3)  # the producer runs ahead until this consumer's queue is full
        ahead.append(len(produced))
        return sum(1 for _ in it)

    def source():
        for i in range(100):
            produced.append(i)
            yield i

    assert fan_out(source(), [slow], depth=3) == [100]
    assert ahead[0] <= 3 + 1  # the queue, plus the item waiting to be put


@pytest.mark.parametrize("n", [0, 1])
def test_short_streams(n):
    assert fan_out(iter(range(n)), [list, list]) == [list(range(n)), list(range(n))]


def test_a_consumer_that_rebinds_a_field_cannot_change_what_the_others_see():
    """A format writer that replaces a frame's pixels (as a tampering test format does) must not
    reach the other writers: each gets its own copy of every item."""
    import dataclasses

    @dataclasses.dataclass
    class Item:
        value: int

    def tamper(it):
        out = []
        for item in it:
            item.value = -1
            out.append(item.value)
        return out

    def honest(it):
        return [item.value for item in it]

    items = [Item(i) for i in range(50)]
    results = fan_out(iter(items), [tamper, honest], copy=dataclasses.replace)
    assert results[0] == [-1] * 50
    assert results[1] == list(range(50))
