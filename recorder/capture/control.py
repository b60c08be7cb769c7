"""Control of a running recorder over HTTP on 127.0.0.1: status, split, pause, resume, mark,
snapshot, Prometheus metrics and a health check, for ``thermcap ctl`` and for whoever watches an
unattended box.

Requests only queue work for the recorder's writer thread (see ``Recorder.request_split``), so
no control call can stall capture. With a token configured every route but ``/healthz`` needs
``Authorization: Bearer <token>``; the token is never logged. The address is written to
``ROOT/run/<session>.control.json`` so ``thermcap ctl`` finds it without flags.
"""

from __future__ import annotations

import hmac
import json
import os
import shutil
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from recorder.storage.segments import write_json_atomic

if TYPE_CHECKING:
    from recorder.capture.recorder import Recorder

__all__ = ["ControlServer", "find_control", "metrics_text"]

RUN_DIR = "run"


def metrics_text(rec: Recorder) -> str:
    """The recorder's own Prometheus metrics (text exposition format 0.0.4)."""
    st = rec.status()
    lat = st["write_latency_ms"]
    lines: list[str] = []

    def metric(name: str, kind: str, help_: str, value: Any, labels: str = "") -> None:
        if f"# TYPE {name} " not in "\n".join(lines):
            lines.extend([f"# HELP {name} {help_}", f"# TYPE {name} {kind}"])
        lines.append(f"{name}{labels} {0 if value is None else value}")

    for name, c in st["cameras"].items():  # the sensor id, or the camera's name in a session of several
        cam = f'{{camera="{name}"}}'
        metric("thermcap_recorder_frames_captured_total", "counter", "Frames read from the source",
               c["frames_captured"], cam)
        metric("thermcap_recorder_frames_written_total", "counter", "Frames written to segments",
               c["frames_written"], cam)
        metric("thermcap_recorder_frames_dropped_total", "counter", "Frames dropped (queue full or disk budget)",
               c["frames_dropped"], cam)
        metric("thermcap_recorder_frames_paused_total", "counter", "Frames not recorded while paused",
               c["frames_paused"], cam)
        metric("thermcap_recorder_camera_failed", "gauge", "1 when the camera failed or stalled",
               int(bool(c["error"])), cam)
    metric("thermcap_recorder_sidecars_dropped_total", "counter", "Sidecars dropped",
           sum(n for t, n in st["dropped"].items() if t.endswith("/metadata")))
    metric("thermcap_recorder_queue_depth", "gauge", "Frames waiting for the writer", st["queue_depth"])
    metric("thermcap_recorder_queue_capacity", "gauge", "Capacity of the writer queue", st["queue_capacity"])
    metric("thermcap_recorder_write_latency_p99_seconds", "gauge", "p99 capture-to-disk latency",
           (lat.get("p99") or 0) / 1000)
    metric("thermcap_recorder_segments", "gauge", "Segments started in this session", st["segments"])
    settling = st["segments_settling"]
    metric("thermcap_recorder_segments_settling", "gauge", "Closed segments waiting for fsync and their final name",
           len(settling))
    metric("thermcap_recorder_settle_wait_seconds", "gauge", "How long the oldest of them has waited",
           settling[0]["waiting_s"] if settling else 0)
    metric("thermcap_recorder_paused", "gauge", "1 while paused", int(st["paused"]))
    metric("thermcap_recorder_healthy", "gauge", "1 when healthy (see /healthz)", int(st["healthy"]))
    metric("thermcap_recorder_seconds_since_last_frame", "gauge", "Seconds since the source gave a frame",
           st["seconds_since_last_frame"])
    metric("thermcap_recorder_disk_free_bytes", "gauge", "Free bytes on the data root's filesystem",
           shutil.disk_usage(rec.root).free)
    ring = st.get("ring") or {}
    metric("thermcap_recorder_evicted_bytes_total", "counter", "Bytes deleted by the ring",
           ring.get("evicted_bytes", 0))
    metric("thermcap_recorder_evicted_segments_total", "counter", "Segments deleted by the ring",
           ring.get("evicted_segments", 0))
    metric("thermcap_recorder_ring_blocked", "gauge", "1 when the ring cannot free space", int(ring.get("blocked", 0)))
    metric("thermcap_recorder_events_total", "counter", "Marks, triggers, pauses and splits", st["events"])
    last = st.get("last_event") or {}
    metric("thermcap_recorder_last_event_timestamp_seconds", "gauge", "Time of the last event",
           (last.get("at_ns") or 0) / 1e9)
    live = st.get("live")
    if live is not None:
        metric("thermcap_live_frames_published_total", "counter", "Frames sent to the live view", live["published"])
        metric("thermcap_live_frames_dropped_total", "counter", "Frames the live view let go (the recording kept "
               "them)", live["dropped"])
    return "\n".join(lines) + "\n"


class ControlServer:
    def __init__(self, rec: Recorder, *, host: str = "127.0.0.1", port: int = 0, token: str | None = None,
                 max_dropped: int = 0) -> None:
        self.rec, self.token, self.max_dropped = rec, token or None, max_dropped
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args: Any) -> None:  # quiet: a request line may carry a token
                pass

            def _send(self, code: int, body: Any, ctype: str = "application/json") -> None:
                data = body.encode() if isinstance(body, str) else json.dumps(body, indent=1).encode()
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def _allowed(self) -> bool:
                if server.token is None:
                    return True
                got = self.headers.get("Authorization", "")
                ok = got.startswith("Bearer ") and hmac.compare_digest(got[7:].encode(), server.token.encode())
                if not ok:
                    self._send(401, {"error": "a valid 'Authorization: Bearer <token>' is required"})
                return ok

            def do_GET(self) -> None:
                path = urlsplit(self.path).path
                if path == "/healthz":
                    healthy, reasons = server.rec.health(server.max_dropped)
                    self._send(200 if healthy else 503, {"healthy": healthy, "problems": reasons})
                    return
                if not self._allowed():
                    return
                if path == "/status":
                    self._send(200, server.rec.status())
                elif path == "/metrics":
                    self._send(200, metrics_text(server.rec), "text/plain; version=0.0.4")
                else:
                    self._send(404, {"error": f"no such route {path}"})

            def do_POST(self) -> None:
                if not self._allowed():
                    return
                url = urlsplit(self.path)
                note = (parse_qs(url.query).get("note") or [""])[0]
                n = int(self.headers.get("Content-Length") or 0)
                if n:
                    try:
                        note = str(json.loads(self.rfile.read(min(n, 65536))).get("note", note))
                    except (ValueError, AttributeError):
                        self._send(400, {"error": "the body must be a JSON object like {\"note\": \"...\"}"})
                        return
                rec = server.rec
                if url.path == "/split":
                    rec.request_split()
                    self._send(202, {"split": "requested"})
                elif url.path == "/pause":
                    self._send(200, {"paused": True, "changed": rec.pause()})
                elif url.path == "/resume":
                    self._send(200, {"paused": False, "changed": rec.resume()})
                elif url.path in ("/mark", "/snapshot"):
                    rec.mark(note, reason="manual" if url.path == "/mark" else "snapshot")
                    self._send(202, {"mark": "requested", "note": note})
                else:
                    self._send(404, {"error": f"no such route {url.path}"})

        self.httpd = ThreadingHTTPServer((host, port), Handler)
        self.httpd.daemon_threads = True
        self.url = f"http://{host}:{self.httpd.server_address[1]}"
        self._thread = threading.Thread(target=self.httpd.serve_forever, name="thermcap-control", daemon=True)
        self.address_file = Path(rec.root) / RUN_DIR / f"{rec.session_id}.control.json"

    def start(self) -> ControlServer:
        self._thread.start()
        self.address_file.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(self.address_file, {"url": self.url, "pid": os.getpid(), "session_id": self.rec.session_id,
                                              "token_required": self.token is not None})
        return self

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.address_file.unlink(missing_ok=True)


def find_control(root: str | Path, session: str | None = None) -> dict[str, Any]:
    """The address of the running recorder under ROOT (the only one, or ``session``)."""
    from recorder.exceptions import ThermcapError

    run = Path(root) / RUN_DIR
    found = []
    for p in sorted(run.glob("*.control.json")) if run.is_dir() else []:
        try:
            doc = json.loads(p.read_text())
        except ValueError:
            continue
        try:
            os.kill(int(doc["pid"]), 0)
        except (OSError, KeyError, ValueError):
            continue  # left by a recorder that died
        if session is None or doc.get("session_id") == session:
            found.append(doc)
    if not found:
        raise ThermcapError(f"no running recorder with a control endpoint under {root}"
                            + (f" for session {session}" if session else ""))
    if len(found) > 1:
        raise ThermcapError(f"{len(found)} recorders run under {root}: name one with --session "
                            f"({', '.join(d['session_id'] for d in found)})")
    return found[0]
