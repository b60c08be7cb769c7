"""The inspection report: a session's findings, each a number a thermographer signs, and a
provenance block from which ``thermcap report verify`` recomputes every one of them.

A finding is a detected target at the frame where it was hottest (one per target id, the
hottest first); the session's analysis events (crossovers, slew-to-cue) are listed beside them
as context. For each finding: the frame, its time and
sha256, the target's box, the maximum temperature in the box, the reference (the median of a
ring 3 to 10 pixels around the box, the local background), ΔT = maximum - reference, the
position where the importer kept one, and the radiometric model version the temperatures used.
The numbers are computed here from the stored counts, not copied from the detector.

``verify_inspection`` reads the JSON twin (or the PDF, which names the JSON's sha256), takes
each frame again from the session (its MCAP segments or, once they are deleted, its archive),
checks its hash, recomputes each number with the model version the report names, and says for
each finding whether it still holds.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder import __version__
from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.exports.files import _positions
from thermcap.recorder.icd.names import iso_utc
from thermcap.recorder.radiometry.params import read_versions
from thermcap.recorder.radiometry.session import SessionTemperatures
from thermcap.recorder.storage.digest import frame_sha256
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

__all__ = ["Finding", "InspectionReport", "VerifyResult", "build_inspection", "verify_inspection"]

RING = (3, 10)
FORMAT = "thermcap inspection report 1"


@dataclass
class Finding:
    frame: int
    time: str
    target_id: str
    classification: str | None
    box: list[int]  # x0, y0, x1, y1, inclusive
    max_c: float
    reference_c: float
    delta_t_c: float
    model_version: int
    frame_sha256: str
    position: dict[str, Any] | None = None


@dataclass
class InspectionReport:
    session_id: str
    findings: list[Finding]
    events: list[dict[str, Any]] = field(default_factory=list)
    provenance: dict[str, Any] = field(default_factory=dict)
    images: dict[int, np.ndarray] = field(default_factory=dict, repr=False)  # frame -> °C, for the PDF

    def to_dict(self) -> dict[str, Any]:
        return {"format": FORMAT, "session_id": self.session_id, "findings": [asdict(f) for f in self.findings],
                "events": self.events, "provenance": self.provenance}


@dataclass
class VerifyResult:
    holds: bool
    checks: list[dict[str, Any]]


def _numbers(temps: np.ndarray, box: list[int]) -> tuple[float, float, float]:
    """(max in the box, median of the ring around it, their difference), rounded as reported;
    pixels without a temperature (NaN: the session's bad pixels) are in none of them."""
    h, w = temps.shape
    x0, y0, x1, y1 = box
    inner = temps[max(0, y0):y1 + 1, max(0, x0):x1 + 1]
    inner = inner[np.isfinite(inner)]
    if inner.size == 0:
        raise ThermcapError(f"box {box} holds no pixel with a temperature in the {w}x{h} frame")
    ring = np.zeros(temps.shape, bool)
    ring[max(0, y0 - RING[1]):y1 + RING[1] + 1, max(0, x0 - RING[1]):x1 + RING[1] + 1] = True
    ring[max(0, y0 - RING[0]):y1 + RING[0] + 1, max(0, x0 - RING[0]):x1 + RING[0] + 1] = False
    ring &= np.isfinite(temps)
    ref = float(np.median(temps[ring])) if ring.any() else float(np.nanmedian(temps))
    top = float(inner.max())
    return round(top, 3), round(ref, 3), round(top - ref, 3)


def _temperatures(session_dir: Path, meta: dict[str, Any], version: int | None) -> SessionTemperatures:
    """The one place temperatures come from: the version asked for (None: the latest covering
    each frame), the session's bad pixels NaN."""
    try:
        return SessionTemperatures.of(session_dir, meta, version=version)
    except ValueError:
        raise ThermcapError(f"{session_dir}: the report names radiometric model version {version}, which the "
                            f"session no longer has") from None


def build_inspection(session_dir: str | Path, *, max_findings: int = 12) -> InspectionReport:
    session_dir = Path(session_dir)
    meta = read_session_meta(session_dir)
    events = []
    with contextlib.suppress(OSError, ValueError):  # no analysis yet: no events to list
        events = json.loads((session_dir / "events.json").read_text()).get("events", [])
    best: dict[str, tuple[float, int, dict[str, Any], np.ndarray, int]] = {}
    for fr in iter_session_frames(session_dir):
        for t in fr.sidecar_dict().get("targets") or []:
            tid, top, bbox = t.get("target_id"), t.get("max_temp_c"), t.get("bbox")
            if tid is None or top is None or not bbox or len(bbox) != 4:
                continue
            if tid not in best or top > best[tid][0]:
                best[tid] = (float(top), fr.index, t, fr.pixels.copy(), fr.log_time)
    positions = _positions(session_dir)
    findings = []
    images: dict[int, np.ndarray] = {}
    temps_of = _temperatures(session_dir, meta, None)
    for tid, (_, index, target, pixels, log_time) in sorted(best.items(), key=lambda kv: -kv[1][0])[:max_findings]:
        ft = temps_of.celsius(index, pixels)
        temps, version = ft.celsius.astype(np.float64), ft.model_version
        box = [int(v) for v in target["bbox"]]
        top, ref, dt = _numbers(temps, box)
        images[index] = temps
        findings.append(Finding(index, iso_utc(log_time), str(tid), target.get("classification"), box, top, ref, dt,
                                version, frame_sha256(pixels), positions.get(log_time)))
    provenance = {"thermcap": __version__, "generated_at": iso_utc(time.time_ns()),
                  "radiometric_model": meta.get("radiometric_model"),
                  "model_versions": [v.to_dict() for v in read_versions(session_dir)],
                  "reference": f"median of a ring {RING[0]}..{RING[1]} px around the box",
                  "verify": "thermcap report verify <this file>"}
    context = [{"kind": e.get("kind"), "start": iso_utc(int(e["start_ns"])), "end": iso_utc(int(e["end_ns"]))}
               for e in events if isinstance(e, dict) and e.get("start_ns") is not None and e.get("end_ns") is not None]
    return InspectionReport(meta.get("session_id", session_dir.name), findings, context, provenance, images)


def json_sha256_in_pdf(pdf: Path) -> str | None:
    m = re.search(rb"json-sha256=([0-9a-f]{64})", pdf.read_bytes())
    return m.group(1).decode() if m else None


def verify_inspection(path: str | Path, root: str | Path) -> VerifyResult:
    """Recompute every finding of a report (its JSON twin, or the PDF that names it)."""
    from thermcap.recorder.storage.reader import resolve_session

    path = Path(path)
    if path.suffix.lower() == ".pdf":
        want = json_sha256_in_pdf(path)
        twin = path.with_suffix(".json")
        if want is None:
            raise ThermcapError(f"{path}: not a thermcap inspection report (it names no JSON twin)")
        if not twin.is_file():
            raise ThermcapError(f"{path}: its JSON twin {twin.name} is not beside it")
        if hashlib.sha256(twin.read_bytes()).hexdigest() != want:
            return VerifyResult(False, [{"check": "json twin", "holds": False,
                                         "why": f"{twin.name} is not the JSON this PDF was made with"}])
        path = twin
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ThermcapError(f"{path}: not readable as a report ({exc})") from None
    if doc.get("format") != FORMAT:
        raise ThermcapError(f"{path}: not a thermcap inspection report")
    session_dir = resolve_session(doc["session_id"], root)
    meta = read_session_meta(session_dir)
    wanted = {int(f["frame"]) for f in doc["findings"]}
    frames = {fr.index: fr.pixels.copy() for fr in iter_session_frames(session_dir) if fr.index in wanted}
    checks = []
    by_version: dict[int, SessionTemperatures] = {}
    for f in doc["findings"]:
        pixels = frames.get(int(f["frame"]))
        if pixels is None:
            checks.append({"frame": f["frame"], "target_id": f["target_id"], "holds": False,
                           "why": "the session no longer has this frame"})
            continue
        if frame_sha256(pixels) != f["frame_sha256"]:
            checks.append({"frame": f["frame"], "target_id": f["target_id"], "holds": False,
                           "why": "the frame's sha256 differs: the stored counts changed"})
            continue
        version = int(f["model_version"])
        if version not in by_version:
            by_version[version] = _temperatures(session_dir, meta, version)
        temps = by_version[version].celsius(int(f["frame"]), pixels).celsius.astype(np.float64)
        top, ref, dt = _numbers(temps, f["box"])
        differs = [f"{k} {f[k]} -> {v}" for k, v in (("max_c", top), ("reference_c", ref), ("delta_t_c", dt))
                   if abs(float(f[k]) - v) > 5e-4]
        checks.append({"frame": f["frame"], "target_id": f["target_id"], "holds": not differs,
                       "why": "; ".join(differs) or f"recomputed from the counts with model version "
                                                    f"{f['model_version']}: the same"})
    return VerifyResult(all(c["holds"] for c in checks), checks)
