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

from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.manifest import load_manifest

__all__ = ["DEFAULT_PRICES", "KINDS", "RECOMMENDATION_RULE", "audit_sessions", "load_prices", "project",
           "render_markdown", "render_plain", "session_kind", "table_rows"]

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


#: Why a kind of session gets its own figures: an hour of video and a folder of still images are
#: different things to keep, so the audit never averages one with the other.
KINDS = {"continuous": "recordings and imported sequences (SEQ, CSQ, raw): frames at a steady rate; "
                       "figures per recorded hour",
         "stills": "imported still images (R-JPEG, FLIR JPEG, single FFF or TIFF): one frame per file; "
                   "figures per image"}
RECOMMENDATION_RULE = ("per sensor and kind: the verified lossless format with the fewest bytes (per recorded hour "
                       "for continuous sessions, per image for stills); the MCAP source is shown, never recommended")


def session_kind(meta: dict[str, Any], frames: int) -> str:
    """``stills`` where an importer made one frame of each still file, else ``continuous``."""
    source = meta.get("source") or {}
    if isinstance(source, dict) and source.get("source") == "import" and frames <= int(source.get("files") or 0):
        return "stills"
    return "continuous"


def _session_row(session_dir: Path, prices: dict[str, dict[str, Any]]) -> dict[str, Any]:
    from thermcap.recorder.storage.reader import read_session_meta

    m = load_manifest(session_dir)
    frames = m["frames"].get("timestamps_ns") or []
    src = m.get("source", {})
    try:
        meta = read_session_meta(session_dir)
    except Exception:  # the archive alone is left: its copy of the session's record
        meta = m.get("session", {})
    sensor = meta.get("sensor") or m.get("session", {}).get("sensor") or {}
    fps = sensor.get("frame_rate_hz") or 60.0
    kind = session_kind(meta, len(frames))
    hours = ((frames[-1] - frames[0]) / 1e9 + 1 / fps) / 3600 if len(frames) > 1 else len(frames) / fps / 3600
    raw = src.get("raw_bytes", 0)
    formats: dict[str, dict[str, Any]] = {}
    for fid, e in m["formats"].items():
        formats[fid] = {"bytes": e["bytes"], "objects": e["objects"], "compression_ratio": e.get("compression_ratio"),
                        "verified": bool(e["verified"]) and not e.get("damaged")}
    if not src.get("deleted") and src.get("segments"):
        mcap_bytes = sum(s["bytes"] for s in src["segments"])
        formats["mcap"] = {"bytes": mcap_bytes, "objects": len(src["segments"]),
                           "compression_ratio": round(raw / mcap_bytes, 4) if mcap_bytes else None, "verified": True}
    return {"session_id": m["session_id"], "sensor": sensor.get("model") or "unknown", "kind": kind,
            "frames": len(frames), "hours": round(hours, 6) if kind == "continuous" else None,
            "raw_bytes": raw, "formats": formats}


def audit_sessions(session_dirs: list[Path], prices: dict[str, dict[str, Any]],
                   left_out: list[dict[str, str]] | None = None) -> dict[str, Any]:
    """Figures per (sensor, kind) group, never across groups; ``left_out`` (session, why) is
    carried into the report, with the sessions that could not be read added to it."""
    left = list(left_out or [])
    rows = []
    for d in session_dirs:
        try:
            rows.append(_session_row(d, prices))
        except (ArchiveError, KeyError, ValueError) as exc:
            left.append({"session": d.name, "why": f"its manifest cannot be read ({exc})"})
    groups: dict[tuple[str, str], dict[str, Any]] = {}
    for r in rows:
        g = groups.setdefault((r["sensor"], r["kind"]), {
            "sensor": r["sensor"], "kind": r["kind"], "sessions": 0, "frames": 0, "hours": 0.0, "raw_bytes": 0,
            "formats": defaultdict(lambda: {"bytes": 0, "objects": 0, "sessions": 0, "all_verified": True})})
        g["sessions"] += 1
        g["frames"] += r["frames"]
        g["hours"] += r["hours"] or 0.0
        g["raw_bytes"] += r["raw_bytes"]
        for fid, f in r["formats"].items():
            agg = g["formats"][fid]
            agg["bytes"] += f["bytes"]
            agg["objects"] += f["objects"]
            agg["sessions"] += 1
            agg["all_verified"] &= f["verified"]
    out_groups = []
    for (_sensor, kind), g in sorted(groups.items()):
        fmts = {}
        for fid, a in g["formats"].items():
            # a format only some of the group's sessions have is not compared with the others
            complete = a["sessions"] == g["sessions"]
            if kind == "continuous":
                per = {"gib_per_recorded_hour": round(a["bytes"] / GIB / g["hours"], 4) if g["hours"] else None}
            else:
                per = {"bytes_per_image": round(a["bytes"] / g["frames"]) if g["frames"] else None}
            ratio = round(g["raw_bytes"] / a["bytes"], 4) if a["bytes"] and complete else None
            fmts[fid] = {**a, **per, "covers_every_session": complete, "compression_ratio": ratio,
                         "cost": costs(a["bytes"], a["objects"], prices)}
        candidates = {k: v for k, v in fmts.items() if v["all_verified"] and v["covers_every_session"] and k != "mcap"}
        best = min(candidates, key=lambda k: candidates[k]["bytes"]) if candidates else None
        out_groups.append({**{k: v for k, v in g.items() if k != "formats"},
                           "hours": round(g["hours"], 6) if kind == "continuous" else None,
                           "formats": fmts, "recommended_format": best})
    return {"groups": out_groups, "sessions": rows, "left_out": left, "kinds": KINDS,
            "recommendation_rule": RECOMMENDATION_RULE, "prices": prices,
            "units": "bytes; USD; storage per GiB-month; 1 GiB = 2^30 bytes"}


def project(bytes_per_hour: dict[str, float], objects_per_hour: dict[str, float], *, cameras: int,
            hours_per_day: float, days: int = 365, prices: dict[str, dict[str, Any]],
            retention_days: int | None = None) -> dict[str, Any]:
    """N cameras recording H hours a day for ``days``, each day's data kept ``retention_days``
    (default: all of it, for the whole period). Assumes a steady rate of new data
    (``cameras * hours_per_day`` recorded hours a day, at the sample's bytes per hour): what is
    stored grows by the same amount each day until the retention starts deleting, then stays
    flat. Gives the running monthly bill at the end of the period and the total paid over it."""
    out = {}
    kept_days = days if retention_days is None else min(days, retention_days)
    months = days / (365 / 12)
    for fid, bph in bytes_per_hour.items():
        per_day = bph * cameras * hours_per_day
        objects_per_day = objects_per_hour.get(fid, 0) * cameras * hours_per_day
        stored_end = per_day * kept_days
        # GiB-days: growing for kept_days (a triangle), then flat at the retained volume
        gib_days = (per_day * kept_days * kept_days / 2 + per_day * kept_days * (days - kept_days)) / GIB
        tiers = {}
        for name, t in prices.items():
            tiers[name] = {"monthly_at_end": round(stored_end / GIB * t["storage"], 2),
                           "storage_total": round(gib_days / (365 / 12) * t["storage"], 2),
                           "put_total": round(objects_per_day * days / 1000 * t["put"], 2),
                           "retrieve_all_once": round(stored_end / GIB * t["retrieval"]
                                                      + _egress(t, stored_end / GIB), 2)}
        out[fid] = {"recorded_bytes": round(per_day * days), "stored_bytes_at_end": round(stored_end),
                    "tib_at_end": round(stored_end / 1024**4, 3), "objects": round(objects_per_day * days),
                    "cost": tiers}
    return {"cameras": cameras, "hours_per_day": hours_per_day, "days": days, "months": round(months, 3),
            "retention_days": retention_days,
            "assumes": (f"{cameras} cameras x {hours_per_day:g} h a day of new recordings every day for {days} days "
                        f"at the sample's bytes per recorded hour; "
                        + (f"each day's data deleted after {retention_days} days" if retention_days
                           else "nothing deleted during the period")),
            "formats": out}


def table_rows(report: dict[str, Any], tier: str = "s3-standard") -> list[tuple[str, ...]]:
    """The audit as rows (one per group and format), for the plain, Markdown and rich renderings."""
    label = report["prices"].get(tier, {}).get("label", tier)
    rows: list[tuple[str, ...]] = [("sensor", "kind", "format", "sessions", "per hour / per image", "ratio",
                                    f"{label} $/month", "note")]
    for g in report["groups"]:
        for fid, f in sorted(g["formats"].items(), key=lambda kv: kv[1]["bytes"]):
            per = f"{f['gib_per_recorded_hour']:.2f} GiB/h" if g["kind"] == "continuous" and \
                f.get("gib_per_recorded_hour") is not None else \
                f"{f['bytes_per_image'] / 1e3:,.0f} KB/image" if f.get("bytes_per_image") is not None else "-"
            note = "recommended" if fid == g["recommended_format"] else \
                "unverified" if not f["all_verified"] else "" if f["covers_every_session"] else "not every session"
            rows.append((g["sensor"], g["kind"], fid, str(f["sessions"]), per,
                         f"{f['compression_ratio']:.2f}" if f["compression_ratio"] else "-",
                         f"{f['cost'][tier]['storage_per_month']:.4f}" if tier in f["cost"] else "-", note))
    return rows


def render_plain(report: dict[str, Any]) -> str:
    """An aligned table, the groups' recommendations with their rule, and what was left out."""
    rows = table_rows(report)
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i < 3 or i == 7 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths,
                                                                                                 strict=True))).rstrip()
             for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append("")
    lines.append(f"rule: {report['recommendation_rule']}")
    for left in report["left_out"]:
        lines.append(f"left out: {left['session']}: {left['why']}")
    return "\n".join(lines)


def render_markdown(report: dict[str, Any]) -> str:
    rows = table_rows(report)
    head, body = rows[0], rows[1:]
    lines = ["| " + " | ".join(h or "note" for h in head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(c for c in r) + " |" for r in body]
    lines.append("")
    lines.append(f"Rule: {report['recommendation_rule']}.")
    for left in report["left_out"]:
        lines.append(f"- left out: {left['session']}: {left['why']}")
    return "\n".join(lines)
