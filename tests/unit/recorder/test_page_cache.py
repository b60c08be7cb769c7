"""bench.page_cache.prime writes what it is asked to, through the page cache, and leaves nothing."""

from __future__ import annotations

import os

import pytest

from thermcap.benches.page_cache import prime


@pytest.mark.parametrize("nbytes", [0, 1, (4 << 20) + 3, 9 << 20])
def test_prime_writes_the_bytes_and_removes_its_file(tmp_path, monkeypatch, nbytes):
    written: list[int] = []
    real_write = os.write

    def counting(fd: int, data: bytes) -> int:
        n = real_write(fd, data)
        written.append(n)
        return n

    monkeypatch.setattr(os, "write", counting)
    cost = prime(tmp_path, nbytes)
    assert sum(written) == nbytes
    assert cost >= 0
    assert list(tmp_path.iterdir()) == []


def test_prime_in_a_missing_folder_fails_and_says_where(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        prime(tmp_path / "nowhere", 10)
