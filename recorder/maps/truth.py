"""Detections against a survey's ground truth: the DJI survey's question (which animals did the
flight find, and where) as one comparison.

Truth is a GeoJSON FeatureCollection of points or a CSV with ``latitude,longitude`` columns (an
``id`` column optional). Each truth point is matched to the nearest unmatched hot spot within
``radius_m`` (greedy, nearest pairs first), in the flight's UTM zone.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError

__all__ = ["TruthReport", "compare_with_truth", "read_truth"]


@dataclass
class TruthReport:
    truth: int
    detections: int
    matched: int
    radius_m: float
    precision: float | None
    recall: float | None
    matches: list[dict[str, Any]] = field(default_factory=list)
    missed: list[dict[str, Any]] = field(default_factory=list)
    false_detections: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def read_truth(path: str | Path) -> list[dict[str, Any]]:
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise ThermcapError(f"{p}: cannot read the ground truth ({exc.strerror or exc})") from None
    points = []
    try:
        if p.suffix.lower() in (".json", ".geojson"):
            for i, f in enumerate(json.loads(text).get("features", [])):
                lon, lat = f["geometry"]["coordinates"][:2]
                points.append({"id": (f.get("properties") or {}).get("id", i), "latitude": float(lat),
                               "longitude": float(lon)})
        else:
            for i, row in enumerate(csv.DictReader(text.splitlines())):
                points.append({"id": row.get("id", i), "latitude": float(row["latitude"]),
                               "longitude": float(row["longitude"])})
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise ThermcapError(f"{p}: not GeoJSON points or a latitude,longitude CSV ({type(exc).__name__}: {exc})") \
            from None
    if not points:
        raise ThermcapError(f"{p}: no ground-truth points")
    return points


def compare_with_truth(hot_spots: list[dict[str, Any]], truth: list[dict[str, Any]], epsg: int,
                       radius_m: float) -> TruthReport:
    from pyproj import Transformer

    to_utm = Transformer.from_crs(4326, epsg, always_xy=True)
    tpos = [to_utm.transform(t["longitude"], t["latitude"]) for t in truth]
    # by longitude and latitude: hot spots of a flight across a zone boundary are each in their own zone
    hpos = [to_utm.transform(h["longitude"], h["latitude"]) for h in hot_spots]
    pairs = sorted((math.dist(tp, hp), ti, hi) for ti, tp in enumerate(tpos) for hi, hp in enumerate(hpos))
    used_t: set[int] = set()
    used_h: set[int] = set()
    matches = []
    for d, ti, hi in pairs:
        if d > radius_m:
            break
        if ti in used_t or hi in used_h:
            continue
        used_t.add(ti)
        used_h.add(hi)
        matches.append({"truth_id": truth[ti]["id"], "distance_m": round(d, 3), "frame_index": hot_spots[hi].get(
            "frame_index"), "max_temp_c": hot_spots[hi].get("max_temp_c")})
    n = len(matches)
    return TruthReport(truth=len(truth), detections=len(hot_spots), matched=n, radius_m=radius_m,
                       precision=round(n / len(hot_spots), 4) if hot_spots else None,
                       recall=round(n / len(truth), 4) if truth else None, matches=matches,
                       missed=[truth[i] for i in range(len(truth)) if i not in used_t],
                       false_detections=[h for i, h in enumerate(hot_spots) if i not in used_h])
