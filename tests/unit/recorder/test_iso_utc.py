"""iso_utc keeps the last formatted second: every time it prints must still be its own."""

from __future__ import annotations

import random
import threading
from datetime import UTC, datetime

from thermcap.recorder.icd.names import iso_utc, parse_rfc3339


def _reference(ns: int) -> str:
    sec, frac = divmod(ns, 1_000_000_000)
    return datetime.fromtimestamp(sec, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S") + f".{frac:09d}Z"


def test_times_in_any_order_across_seconds() -> None:
    rng = random.Random(5)
    base = 1_700_000_000_000_000_000
    times = [0, -1, 999_999_999, 1_000_000_000, base - 1, base, base + 1]
    times += [base + rng.randrange(-3_000_000_000, 3_000_000_000) for _ in range(2000)]  # back and forth
    times += [rng.randrange(-(2**62), 2**62) // 100 for _ in range(500)]
    for ns in times:
        text = iso_utc(ns)
        assert text == _reference(ns), ns
        assert parse_rfc3339(text) == ns


def test_threads_formatting_other_seconds_do_not_mix() -> None:
    errors: list[str] = []

    def run(offset_s: int) -> None:
        for i in range(3000):
            ns = (1_600_000_000 + offset_s + i % 3) * 1_000_000_000 + i
            if iso_utc(ns) != _reference(ns):
                errors.append(f"{ns}: {iso_utc(ns)}")

    threads = [threading.Thread(target=run, args=(k * 100,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
