"""``thermcap audit``: what the archives cost to keep, per session, per sensor and per format.

Prices are list prices (USD, 2026) from ``DEFAULT_PRICES``, per GiB-month (cloud "GB" are
2^30 bytes); a user overrides any of them with a JSON file of the same shape (``--prices``).
Storage cost scales with bytes, PUT cost with objects (why per-segment containers matter: an
hour of per-frame PNGs would be 216,000 PUTs), and retrieval with bytes read back out.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

from archive.exceptions import ArchiveError
from archive.manifest import load_manifest

__all__ = ["DEFAULT_PRICES", "audit_sessions", "load_prices", "project", "render_markdown"]

GIB = 1024**3

DEFAULT_PRICES: dict[str, dict[str, Any]] = {
    # storage: USD per GiB-month; put: USD per 1,000 PUT/upload requests; retrieval: USD per GiB read
    # back (tier fee); egress: USD per GiB out to the internet after egress_free_gib free per month.
    "s3-standard": {"label": "S3 Standard", "storage": 0.023, "put": 0.005, "retrieval": 0.0,
                    "egress": 0.09, "egress_free_gib": 100},
    "s3-standard-ia": {"label": "S3 Standard-IA", "storage": 0.0125, "put": 0.01, "retrieval": 0.01,
                       "egress": 0.09, "egress_free_gib": 100},
    "s3-glacier-ir": {"label": "S3 Glacier Instant Retrieval", "storage": 0.004, "put": 0.02, "retrieval": 0.03,
                      "egress": 0.09, "egress_free_gib": 100},
    "s3-deep-archive": {"label": "S3 Glacier Deep Archive", "storage": 0.00099, "put": 0.05, "retrieval": 0.02,
                        "egress": 0.09, "egress_free_gib": 100},
    "r2": {"label": "Cloudflare R2", "storage": 0.015, "put": 0.0045, "retrieval": 0.0, "egress": 0.0,
           "egress_free_gib": 0},
    "b2": {"label": "Backblaze B2", "storage": 0.006, "put": 0.0, "retrieval": 0.0, "egress": 0.01,
           "egress_free_gib": None},  # None: free up to 3x the data stored
}


def load_prices(path: str | Path | None) -> dict[str, dict[str, Any]]:
    prices = json.loads(json.dumps(DEFAULT_PRICES))
    if path is None:
        return prices
    try:
        override = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise ArchiveError(f"{path}: cannot read the price table ({exc})") from exc
    if not isinstance(override, dict):
        raise ArchiveError(f"{path}: the price table must be an object of tiers")
    for tier, values in override.items():
        if not isinstance(values, dict):
            raise ArchiveError(f"{path}: tier {tier!r} must be an object")
        prices.setdefault(tier, {"label": tier, "storage": 0.0, "put": 0.0, "retrieval": 0.0, "egress": 0.0,
                                 "egress_free_gib": 0}).update(values)
    return prices


def _egress(tier: dict[str, Any], gib: float) -> float:
    free = tier.get("egress_free_gib")
    if free is None:  # B2: free while monthly egress stays under 3x the data stored
        return 0.0
    return max(0.0, gib - free) * tier["egress"]


def costs(nbytes: int, objects: int, prices: dict[str, dict[str, Any]]) -> dict[str, dict[str, float]]:
    gib = nbytes / GIB
    return {name: {"storage_per_month": gib * t["storage"],
                   "put_once": objects / 1000 * t["put"],
                   "retrieve_once": gib * t["retrieval"] + _egress(t, gib)}
            for name, t in prices.items()}


def _session_row(session_dir: Path, prices: dict[str, dict[str, Any]]) -> dict[str, Any]:
    m = load_manifest(session_dir)
    frames = m["frames"].get("timestamps_ns") or []
    src = m.get("source", {})
    fps = (m.get("session", {}).get("sensor") or {}).get("frame_rate_hz") or 60.0
    hours = ((frames[-1] - frames[0]) / 1e9 + 1 / fps) / 3600 if len(frames) > 1 else len(frames) / fps / 3600
    raw = src.get("raw_bytes", 0)
    formats: dict[str, dict[str, Any]] = {}
    for fid, e in m["formats"].items():
        formats[fid] = {"bytes": e["bytes"], "objects": e["objects"], "compression_ratio": e.get("compression_ratio"),
                        "bytes_per_hour": round(e["bytes"] / hours) if hours else None, "verified": e["verified"],
                        "cost": costs(e["bytes"], e["objects"], prices)}
    if not src.get("deleted") and src.get("segments"):
        mcap_bytes = sum(s["bytes"] for s in src["segments"])
        formats["mcap"] = {"bytes": mcap_bytes, "objects": len(src["segments"]),
                           "compression_ratio": round(raw / mcap_bytes, 4) if mcap_bytes else None,
                           "bytes_per_hour": round(mcap_bytes / hours) if hours else None, "verified": True,
                           "cost": costs(mcap_bytes, len(src["segments"]), prices)}
    verified = {k: v for k, v in formats.items() if v["verified"] and k != "mcap"}
    best = min(verified, key=lambda k: verified[k]["bytes"]) if verified else None
    return {"session_id": m["session_id"], "sensor": (m.get("session", {}).get("sensor") or {}).get("model"),
            "frames": len(frames), "hours": round(hours, 6), "raw_bytes": raw, "formats": formats,
            "recommended_format": best}


def audit_sessions(session_dirs: list[Path], prices: dict[str, dict[str, Any]]) -> dict[str, Any]:
    rows = [_session_row(d, prices) for d in session_dirs]
    by_sensor: dict[str, dict[str, Any]] = defaultdict(lambda: {"hours": 0.0, "frames": 0, "formats": defaultdict(
        lambda: {"bytes": 0, "objects": 0})})
    by_format: dict[str, dict[str, Any]] = defaultdict(lambda: {"bytes": 0, "objects": 0, "hours": 0.0,
                                                                "raw_bytes": 0, "all_verified": True})
    for r in rows:
        s = by_sensor[r["sensor"] or "unknown"]
        s["hours"] += r["hours"]
        s["frames"] += r["frames"]
        for fid, f in r["formats"].items():
            s["formats"][fid]["bytes"] += f["bytes"]
            s["formats"][fid]["objects"] += f["objects"]
            agg = by_format[fid]
            agg["bytes"] += f["bytes"]
            agg["objects"] += f["objects"]
            agg["hours"] += r["hours"]
            agg["raw_bytes"] += r["raw_bytes"]
            agg["all_verified"] &= bool(f["verified"])
    fmt_out = {}
    for fid, a in by_format.items():
        fmt_out[fid] = {**a, "compression_ratio": round(a["raw_bytes"] / a["bytes"], 4) if a["bytes"] else None,
                        "bytes_per_hour": round(a["bytes"] / a["hours"]) if a["hours"] else None,
                        "cost": costs(a["bytes"], a["objects"], prices)}
    candidates = {k: v for k, v in fmt_out.items() if v["all_verified"] and k != "mcap"}
    best = min(candidates, key=lambda k: candidates[k]["bytes"]) if candidates else None
    cheapest_tier = None
    if best:
        tiers = fmt_out[best]["cost"]
        cheapest_tier = min(tiers, key=lambda t: tiers[t]["storage_per_month"])
    return {"sessions": rows,
            "sensors": {k: {**v, "formats": dict(v["formats"])} for k, v in by_sensor.items()},
            "formats": fmt_out, "recommended_format": best, "cheapest_storage_tier": cheapest_tier,
            "prices": prices, "units": "bytes; USD; storage per GiB-month; 1 GiB = 2^30 bytes"}


def project(bytes_per_hour: dict[str, float], objects_per_hour: dict[str, float], *, cameras: int,
            hours_per_day: float, days: int = 365, prices: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """N cameras, H hours a day, for ``days``: volume, the monthly bill at the end, the total paid."""
    out = {}
    months = days / (365 / 12)
    for fid, bph in bytes_per_hour.items():
        total_bytes = bph * cameras * hours_per_day * days
        objects = objects_per_hour.get(fid, 0) * cameras * hours_per_day * days
        gib = total_bytes / GIB
        tiers = {}
        for name, t in prices.items():
            # Data grows linearly, so on average half of it is stored over the period.
            tiers[name] = {"storage_per_month_at_end": round(gib * t["storage"], 2),
                           "storage_total": round(gib * t["storage"] * months / 2, 2),
                           "put_total": round(objects / 1000 * t["put"], 2),
                           "retrieve_all_once": round(gib * t["retrieval"] + _egress(t, gib), 2)}
        out[fid] = {"bytes": round(total_bytes), "tib": round(total_bytes / 1024**4, 3), "objects": round(objects),
                    "cost": tiers}
    return {"cameras": cameras, "hours_per_day": hours_per_day, "days": days, "formats": out}


def render_markdown(report: dict[str, Any]) -> str:
    tiers = list(report["prices"])
    head = "| format | bytes | objects | ratio | GiB per recorded hour | " + " | ".join(
        report["prices"][t]["label"] + " $/month" for t in tiers) + " | PUT $ (S3 Std) | retrieve once $ (S3 Std) |"
    lines = [f"{len(report['sessions'])} session(s); recommended format: **{report['recommended_format']}**, "
             f"cheapest storage tier: {report['prices'].get(report['cheapest_storage_tier'] or '', {}).get('label')}",
             "", head, "|" + "---|" * (len(tiers) + 7)]
    for fid, f in sorted(report["formats"].items(), key=lambda kv: kv[1]["bytes"]):
        bph = f["bytes_per_hour"] / GIB if f["bytes_per_hour"] else 0
        lines.append(f"| {fid}{'' if f['all_verified'] else ' (unverified)'} | {f['bytes']:,} | {f['objects']} | "
                     f"{f['compression_ratio']} | {bph:.1f} | "
                     + " | ".join(f"{f['cost'][t]['storage_per_month']:.4f}" for t in tiers)
                     + f" | {f['cost'].get('s3-standard', {}).get('put_once', 0):.4f} | "
                     f"{f['cost'].get('s3-standard', {}).get('retrieve_once', 0):.4f} |")
    return "\n".join(lines)
