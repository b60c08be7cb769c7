"""``thermcap bench import``: import throughput per format against the floor every importer pays.

The baseline, measured in the same run on the same files, is reading each file and hashing its
bytes (sha256): what any tool that ingests a survey must at least do. ``x base`` is how many times
that floor the whole import costs (detect, parse, check, and record into MCAP through the
recorder). The corpus is the simulator's frames exported as ICD TIFF + JSON pairs, plus, where a
samples folder is given, each real sample copied ``copies`` times.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from thermcap.recorder.importers import ImportFileError, read_file
from thermcap.recorder.importers.dji_sdk import DjiBackend
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["bench_import", "print_table"]


def _simulated_icd(folder: Path, frames: int) -> list[Path]:
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources import SimSource
    from thermcap.recorder.exports.files import export_session

    rec = Recorder(SimSource(frames=frames, paced=False, seed=7), folder / "rec", session_id="bench",
                   analysis=False)
    rec.run()
    export_session(DataRoot.of(folder / "rec").session_dir("bench"), "icd", folder / "icd")
    return sorted((folder / "icd").glob("*.tif*"))


def _sample_corpus(samples: Path, folder: Path, copies: int) -> dict[str, list[Path]]:
    """Each importable sample, copied with the sidecars it needs, grouped by detected format."""
    by_format: dict[str, list[Path]] = {}
    for path in sorted(p for p in samples.rglob("*") if p.is_file()):
        try:
            fmt = read_file(path)[0].format
        except ImportFileError:
            continue  # notes, sidecars, references
        for i in range(copies):
            dst = folder / fmt / f"c{i}"
            dst.mkdir(parents=True, exist_ok=True)
            shutil.copy(path, dst / path.name)
            for side in path.parent.glob(path.name.split("_ir.bin")[0] + "*.json") if fmt == "terraref-bin" else []:
                shutil.copy(side, dst / side.name)
            by_format.setdefault(fmt, []).append(dst / path.name)
    return by_format


def _measure(name: str, files: list[Path], folder: Path, dji_sdk: DjiBackend | None) -> dict[str, Any]:
    from thermcap.recorder.importers.run import import_paths

    size = sum(f.stat().st_size for f in files)
    t0 = time.perf_counter()
    for f in files:
        hashlib.sha256(f.read_bytes()).digest()
    base = time.perf_counter() - t0
    t0 = time.perf_counter()
    report = import_paths([str(f) for f in files], folder / f"root-{name}", analysis=False, dji_sdk=dji_sdk)
    took = time.perf_counter() - t0
    if report.failed:
        raise ImportFileError(f"bench corpus {name}: {report.failed[0]['error']}")
    extra = {}
    if dji_sdk is not None:  # the SDK alone on the same files: what the import adds on top of it
        t0 = time.perf_counter()
        dji_sdk.measure([str(f) for f in files])
        extra = {"sdk_alone_files_per_s": round(len(files) / (time.perf_counter() - t0), 1)}
    return {**extra, "format": name, "files": len(files), "mb": round(size / 1e6, 1),
            "files_per_s": round(len(files) / took, 1), "mb_per_s": round(size / 1e6 / took, 1),
            "baseline_files_per_s": round(len(files) / base, 1), "x_baseline": round(took / base, 1),
            "sessions": len(report.sessions)}


def bench_import(*, frames: int = 300, samples: str | Path | None = None, copies: int = 8,
                 dji_sdk: DjiBackend | None = None) -> list[dict[str, Any]]:
    with tempfile.TemporaryDirectory(prefix="thermcap-bench-import-") as tmp:
        folder = Path(tmp)
        rows = [_measure("icd-tiff (simulated)", _simulated_icd(folder, frames), folder, None)]
        if samples:
            fff = next(Path(samples).rglob("*.fff"), None)
            if fff is not None:  # one long SEQ: frames decoded one at a time, linear in its length
                seq = folder / "long.seq"
                seq.write_bytes(fff.read_bytes() * (copies * 40))
                rows.append(_measure(f"flir-seq ({copies * 40} frames)", [seq], folder, None))
            for fmt, files in _sample_corpus(Path(samples), folder / "corpus", copies).items():
                rows.append(_measure(fmt, files, folder, None))
                if fmt == "dji-rjpeg" and dji_sdk is not None:
                    rows.append(_measure("dji-rjpeg + SDK", files, folder, dji_sdk))
        return rows


def print_table(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'format':>24} {'files':>6} {'MB':>7} {'files/s':>8} {'MB/s':>7} {'base files/s':>13} {'x base':>7}",
             "(base = read + sha256 of the same files, same run; x base = import time / base time)"]
    for r in rows:
        lines.append(f"{r['format']:>24} {r['files']:>6} {r['mb']:>7} {r['files_per_s']:>8} {r['mb_per_s']:>7} "
                     f"{r['baseline_files_per_s']:>13} {r['x_baseline']:>7}")
        if "sdk_alone_files_per_s" in r:
            lines.append(f"{'':>24} (the SDK backend alone on the same files: {r['sdk_alone_files_per_s']} files/s)")
    return "\n".join(lines)
