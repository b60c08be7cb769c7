"""``thermcap bench import`` runs end to end and reports every format it found."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_bench_import_reports_each_format_against_its_baseline(samples):
    r = run_cli("bench", "import", "--frames", "12", "--samples", str(samples), "--copies", "2", "--dji-sdk", "off",
                "--json", timeout=300)
    assert r.returncode == 0, r.stderr
    rows = {row["format"]: row for row in json.loads(r.stdout)}
    assert {"icd-tiff (simulated)", "dji-rjpeg", "flir-rjpeg", "flir-fff", "terraref-bin"} <= set(rows)
    assert rows["icd-tiff (simulated)"]["files"] == 12
    assert rows["dji-rjpeg"]["files"] == 10
    assert rows["flir-seq (80 frames)"]["files"] == 1
    assert rows["flir-seq (80 frames)"]["sessions"] == 1
    for row in rows.values():
        assert row["files_per_s"] > 0
        assert row["baseline_files_per_s"] > 0
        assert row["x_baseline"] > 0
        assert row["sessions"] >= 1
