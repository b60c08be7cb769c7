"""The frame stream read once and teed to every format writer (archive.fanout)."""

from __future__ import annotations

import contextlib

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


@pytest.mark.parametrize("turn", [1, 3, 8])
def test_what_was_read_before_a_source_error_still_reaches_every_consumer(turn):
    """Items are handed on in batches; the items of a batch the error cut short come first."""
    def source():
        yield from range(5)
        raise OSError("segment unreadable")

    def consumer(it):
        seen = []
        try:
            for item in it:
                seen.append(item)
        except OSError:
            return seen
        return "no error"

    assert fan_out(source(), [consumer, consumer], turn=turn) == [list(range(5))] * 2


def test_a_copy_that_fails_ends_every_consumer_instead_of_leaving_it_waiting():
    def copy(item):
        if item == 4:
            raise MemoryError("no room for a copy")
        return item

    results = fan_out(iter(range(10)), [list, list], copy=copy, turn=2)
    assert all(isinstance(r, MemoryError) for r in results)


@pytest.mark.parametrize("depth, turn", [(3, 8), (8, 8), (8, 2), (1, 1)])
def test_memory_is_bounded_by_the_queue_depth(depth, turn):
    """A slow writer holds the producer back: at most its queue's depth is read ahead, and the
    batch the producer holds while it waits (of ``turn`` items, at most ``depth``)."""
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

    assert fan_out(source(), [slow], depth=depth, turn=turn) == [100]
    assert ahead[0] <= depth + min(turn, depth)  # the queue, plus the batch waiting to be put


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


class _Inside:
    """How many consumers are working at once, at most, counted at each item and in each tail."""

    def __init__(self) -> None:
        import threading

        self.lock = threading.Lock()
        self.now = 0
        self.most = 0

    def __enter__(self) -> None:
        with self.lock:
            self.now += 1
            self.most = max(self.most, self.now)

    def __exit__(self, *_exc) -> None:
        with self.lock:
            self.now -= 1


@pytest.mark.parametrize("slots, turn", [(1, 1), (1, 8), (2, 3), (2, 8)])
def test_consumers_take_turns_in_slots_and_every_one_sees_every_item(slots, turn):
    """At most ``slots`` consumers work at once, in the stream and in what they do after it (a
    writer's read-back); each still sees every item once, in order. Three consumers meet at a
    barrier on their first item: teed without turns all three get there together (the count
    reaches 3), taking turns only ``slots`` of them can (the barrier gives up, and they go on)."""
    import threading

    inside = _Inside()
    barrier = threading.Barrier(3, timeout=1.0)

    def consumer(it):
        seen = []
        for item in it:
            with inside:
                if item == 0:
                    with contextlib.suppress(threading.BrokenBarrierError):
                        barrier.wait()
                seen.append(item)
        with inside:  # the tail: a writer reading its files back
            seen.append("tail")
        return seen

    results = fan_out(iter(range(300)), [consumer, consumer, consumer], depth=4, slots=slots, turn=turn)
    assert results == [[*range(300), "tail"]] * 3
    assert inside.most <= slots


def test_without_turns_the_consumers_all_work_at_once():
    """The control for the test above: the barrier of three is met when nothing takes turns."""
    import threading

    inside = _Inside()
    barrier = threading.Barrier(3, timeout=30.0)

    def consumer(it):
        for item in it:
            with inside:
                if item == 0:
                    barrier.wait()
        return True

    assert fan_out(iter(range(20)), [consumer] * 3, slots=None) == [True] * 3
    assert fan_out(iter(range(20)), [consumer] * 3, slots=3) == [True] * 3  # as many slots as consumers
    assert inside.most == 3


@pytest.mark.parametrize("slots", [1, 2])
def test_a_consumer_that_fails_holding_a_slot_gives_it_back(slots):
    """A writer that raises mid-stream leaves its iterator suspended in the exception's
    traceback, still holding its slot: the others must still get every item."""
    def fails(it):
        for i in it:
            if i == 10:
                raise ValueError("writer broke")
        return "never"

    import threading

    out: list = []
    run = threading.Thread(target=lambda: out.append(
        fan_out(iter(range(500)), [fails, fails, list, list], depth=2, slots=slots, turn=4)), daemon=True)
    run.start()
    run.join(timeout=120)  # a slot never given back deadlocks: fail, do not hang the suite
    assert not run.is_alive(), "fan_out deadlocked: a failed consumer kept its slot"
    results = out[0]
    assert isinstance(results[0], ValueError) and isinstance(results[1], ValueError)
    assert results[2] == results[3] == list(range(500))


@pytest.mark.parametrize("kwargs", [{"slots": 0}, {"turn": 0}, {"depth": 0}])
def test_absurd_turns_are_refused(kwargs):
    with pytest.raises(ValueError, match="at least 1"):
        fan_out(iter(range(3)), [list], **kwargs)


def test_the_sources_read_takes_a_slot_too():
    """Reading and hashing the source is work on a core as the codecs' is: with one slot, the
    source does not read its next item while a consumer works. A consumer on its first item
    waits for the source to start reading the next one; the source never can (the wait gives up)."""
    import threading

    inside = _Inside()
    reading = threading.Event()
    caught: list[bool] = []

    def source():
        for i in range(40):
            with inside:
                reading.set()  # reading item i
            yield i

    def consumer(it):
        out = []
        for item in it:
            with inside:
                if item == 0 and not caught:
                    reading.clear()
                    caught.append(reading.wait(timeout=1.0))  # does the source read meanwhile?
            out.append(item)
        return out

    assert fan_out(source(), [consumer, consumer], depth=4, slots=1) == [list(range(40))] * 2
    assert caught == [False] and inside.most == 1
