"""One grammar of sizes for every option that takes one: before, ``500M`` was 500 MiB in
``record`` and 500 MB in ``gc``, and ``gc --max-bytes 500GB`` was refused."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_cli
from thermcap.recorder.sizes import parse_size


@pytest.mark.parametrize(("text", "size"), [
    ("123456", 123456), ("500M", 500 << 20), ("500m", 500 << 20), ("500MiB", 500 << 20), ("500MB", 500 * 10**6),
    ("1.5T", int(1.5 * (1 << 40))), ("2TB", 2 * 10**12), ("20 G", 20 << 30), ("7B", 7), (".5K", 512),
])
def test_the_grammar(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("text", ["", "M", "-5G", "5X", "1e3", "nan", "inf", "5GG", "10iB", "9" * 40 + "T"])
def test_what_is_not_a_size_is_named(text):
    with pytest.raises(ValueError, match=r"size|disk"):
        parse_size(text)


def test_gc_reads_sizes_as_record_does(tmp_path):
    (tmp_path / "sessions").mkdir()
    for text in ("500GB", "500G", "2TiB"):
        r = run_cli("gc", "--root", str(tmp_path), "--max-bytes", text, "--dry-run", "--json")
        assert r.returncode == 0, r.stderr
        json.loads(r.stdout)
    bad = run_cli("gc", "--root", str(tmp_path), "--max-bytes", "lots", "--dry-run")
    assert bad.returncode == 2 and "lots" in bad.stderr and "Traceback" not in bad.stderr
