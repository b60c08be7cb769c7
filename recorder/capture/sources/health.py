"""What a source's ``health()`` says, in words: one reading for the recording's summary, its
exit status, ``ctl status`` and ``info``, whatever the kind of source."""

from __future__ import annotations

from typing import Any

__all__ = ["source_line", "source_losses"]


def source_losses(health: dict[str, Any]) -> list[str]:
    """What the source lost before the recorder saw it; empty when it lost nothing."""
    out = []
    if health.get("gaps"):
        again = (f"; it ended {health['restarts']} times and was started again" if health.get("restarts") else
                 f"; reconnected {health['reconnects']} times" if health.get("reconnects") else "")
        out.append(f"{health['gaps']} gaps without frames from the source ({health.get('gap_s', 0)} s{again}; "
                   f"see the source_gap events)")
    if health.get("incomplete_frames"):
        by = health.get("incomplete_by_status") or {}
        out.append(f"{health['incomplete_frames']} incomplete frames from the source, counted and not written"
                   + (f" ({', '.join(f'{k}: {v}' for k, v in by.items())})" if by else ""))
    if health.get("frames_missed"):
        out.append(f"{health['frames_missed']} frames the camera numbered never arrived (by its frame ids)")
    return out


def source_line(described: dict[str, Any], health: dict[str, Any]) -> str:
    """``source: gige 10.0.0.5 (FLIR A70, serial 123)  2 gaps (7.1 s), 0 incomplete, 40 missed``"""
    kind = described.get("source", "?")
    target = described.get("camera") if kind == "gige" else described.get("command") or described.get("path")
    genicam = described.get("genicam") or {}
    device = " ".join(str(genicam[k]) for k in ("DeviceVendorName", "DeviceModelName") if genicam.get(k))
    serial = genicam.get("DeviceSerialNumber")
    text = f"source: {kind}" + (f" {target}" if target else "") + (
        f" ({device}{f', serial {serial}' if serial else ''})" if device else "")
    if health:
        text += (f"   gaps: {health.get('gaps', 0)} ({health.get('gap_s', 0)} s)"
                 f"   incomplete frames: {health.get('incomplete_frames', 0)}")
        if "frames_missed" in health:
            text += f"   frames missed: {health['frames_missed']}"
    return text
