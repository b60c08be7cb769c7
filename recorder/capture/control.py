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

from thermcap.recorder.loopback import is_loopback
from thermcap.recorder.storage.atomic import write_json_atomic

if TYPE_CHECKING:
    from thermcap.recorder.capture.recorder import Recorder

__all__ = ["MAX_BODY_BYTES", "ControlServer", "find_control", "metrics_text"]

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
    metric("thermcap_recorder_windows_expired_total", "counter", "Event windows the ring let go to keep recording",
           ring.get("windows_expired", 0))
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


#: A control request's body is a note: nothing larger, or nested deeper, is read.
MAX_BODY_BYTES = 16 << 10
MAX_JSON_DEPTH = 8


def _depth(text: str) -> int:
    """How deep brackets nest in a JSON text (checked before parsing: json.loads recurses)."""
    depth = most = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            escaped = not escaped and ch == "\\"
            if ch == '"' and not escaped:
                in_string = False
            continue
        if ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            most = max(most, depth)
        elif ch in "]}":
            depth -= 1
    return most


class _QuietServer(ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A client that hangs up mid-answer is its own business: no traceback in the recorder's log."""
        import sys

        exc = sys.exc_info()[1]
        if isinstance(exc, ConnectionError | TimeoutError):
            return
        super().handle_error(request, client_address)


class ControlServer:
    """``insecure=True`` alone lets it run without a token: any local user (or a web page, through
    a POST no browser preflights) could otherwise pause a recording."""

    def __init__(self, rec: Recorder, *, host: str = "127.0.0.1", port: int = 0, token: str | None = None,
                 max_dropped: int = 0, insecure: bool = False) -> None:
        if not token and not insecure:
            raise ValueError("the control endpoint needs a token: set THERMCAP_CONTROL_TOKEN (or --control-token), "
                             "or pass --control-insecure to run it open to every local user")
        self.rec, self.token, self.max_dropped = rec, token or None, max_dropped
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args: Any) -> None:  # quiet: a request line may carry a token
                pass

            def _send(self, code: int, body: Any, ctype: str = "application/json") -> None:
                data = body.encode() if isinstance(body, str) else json.dumps(body, indent=1).encode()
                try:
                    self.send_response(code)
                    self.send_header("Content-Type", ctype)
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (ConnectionError, TimeoutError):
                    self.close_connection = True  # the client hung up: nothing to tell it

            def _same_origin(self) -> bool:
                """Only requests addressed to this endpoint by its own name: a page elsewhere (its
                Origin) or a DNS name rebound to 127.0.0.1 (its Host) is refused before anything."""
                host = (self.headers.get("Host") or "").strip()
                try:
                    parsed = urlsplit("//" + host)
                    name, port = parsed.hostname, parsed.port
                except ValueError:
                    name = port = None
                if not name or port != server.port or not (is_loopback(name) or name == server.host.strip("[]")):
                    self._send(403, {"error": f"Host {host or '(none)'!r} is not this control endpoint"})
                    return False
                origin = self.headers.get("Origin")
                if origin is not None and origin.rstrip("/") not in server.origins:
                    self._send(403, {"error": f"requests from {origin!r} are not accepted"})
                    return False
                return True

            def _allowed(self) -> bool:
                if not self._same_origin():
                    return False
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
                    if not self._same_origin():
                        return
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
                length = (self.headers.get("Content-Length") or "0").strip()
                if not length.isdigit():
                    self._send(400, {"error": f"Content-Length {length[:40]!r} is not a byte count"})
                    self.close_connection = True
                    return
                n = int(length)
                if n > MAX_BODY_BYTES:
                    self._send(413, {"error": f"the body is {n:,} bytes; at most {MAX_BODY_BYTES:,}"})
                    self.close_connection = True
                    return
                if n:
                    text = self.rfile.read(n).decode("utf-8", errors="replace")
                    try:
                        if _depth(text) > MAX_JSON_DEPTH:
                            raise ValueError("nested too deep")
                        note = str(json.loads(text).get("note", note))
                    except (ValueError, AttributeError, RecursionError):
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
                    keeps = rec.mark(note, reason="manual" if url.path == "/mark" else "snapshot")
                    self._send(202, {"mark": "requested", "note": note, **({"keeps": keeps} if keeps else {})})
                else:
                    self._send(404, {"error": f"no such route {url.path}"})

        self.httpd = _QuietServer((host, port), Handler)
        self.host, self.port = host, self.httpd.server_address[1]
        self.url = f"http://{host}:{self.port}"
        self.origins = {f"http://{h}:{self.port}" for h in ("127.0.0.1", "localhost", "[::1]", host)}
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
    from thermcap.recorder.exceptions import ThermcapError

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
