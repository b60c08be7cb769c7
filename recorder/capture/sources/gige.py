"""A GenICam camera over GigE Vision, through Aravis (``gige:CAMERA``): FLIR A-series,
Teledyne, Workswell and most industrial thermal cameras give Mono16 this way.

CAMERA is what Aravis opens: an IP address (``gige:192.168.1.20``), a device id or name
(``gige:Aravis-Fake-GV01``), or nothing for the first camera found (``gige:``, which discovers
by broadcast on every interface). The size, pixel format and rate are set on the camera, then
any GenICam feature given as a key (``gige:10.0.0.5,ExposureTime=8000,Gain=0``), then read
back: a camera that does not take them is an error before the recording starts.

What a camera does on a vehicle, and what is done about it:
- Every frame keeps the camera's own timestamp and block id beside the host time its first
  packet arrived (``capture.device_timestamp_ns``, ``capture.device_frame_id``); the frame's
  time is the host's.
- A buffer Aravis did not complete (missing packets, a size mismatch, a timeout) is never
  written as a frame: it is counted by its status (``incomplete_frames``).
- Block ids are 16 bits in GigE Vision 1.x and wrap (65535 -> 1): continuity, not loss. A jump
  counts the frames the camera sent that never came (``frames_missed``).
- A camera that goes away raises nothing: the stream goes silent and the device's
  ``control-lost`` comes seconds later. Either (``control-lost``, or no frame for
  ``silence_s``) opens a ``source_gap``; the source then makes a new camera and stream (the old
  objects fail silently) with every setting applied again, retrying with a backoff that doubles
  from ``backoff_s`` to ``max_backoff_s``, and the first frame after closes the gap with its
  duration, the reconnections it took and the frames missed (by block id when the camera's ids
  ran on, by time otherwise).
- The camera's configuration is recorded with the session (device, read-back features), and its
  GenICam XML in every segment from its start (a different camera found after a gap: its XML
  with its first frame).

A live camera cannot wait: when the writer is behind, the recorder drops (and counts) frames
rather than stall the stream. Without CAP_NET_RAW Aravis streams over UDP; the socket buffer is
then sized by Aravis (``socket-buffer`` AUTO), which keeps the rate the default buffer loses.
"""

from __future__ import annotations

import contextlib
import hashlib
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, SensorInfo
from thermcap.recorder.capture.sources.gaps import GapLog
from thermcap.recorder.capture.sources.registry import CameraSettings, SourceKind, register_source
from thermcap.recorder.exceptions import SourceError
from thermcap.recorder.radiometry import DEFAULT_MODEL, RadiometricModel

__all__ = ["GigEOptions", "GigESource", "block_ids_missed"]

#: pixel formats whose pixels are one little-endian uint16 each (PFNC), so the bytes are the counts
SIXTEEN_BIT_FORMATS = ("Mono16", "Mono14", "Mono12", "Mono10")
#: what is read back from the camera and kept with the session, where the camera has it
_CONFIG_FEATURES = ("DeviceVendorName", "DeviceModelName", "DeviceSerialNumber", "DeviceVersion",
                    "DeviceFirmwareVersion", "DeviceID", "PixelFormat", "Width", "Height", "OffsetX", "OffsetY",
                    "AcquisitionMode", "AcquisitionFrameRate", "AcquisitionFramePeriod", "TriggerMode",
                    "ExposureTime", "ExposureTimeAbs", "Gain", "GainRaw", "GevSCPSPacketSize",
                    "GevTimestampTickFrequency")


@dataclass(frozen=True)
class GigEOptions:
    camera: str  # an address, a device id or name; "" for the first found
    width: int = 640
    height: int = 512
    fps: float = 60.0
    pixel_format: str = "Mono16"
    features: tuple[tuple[str, str], ...] = ()  # GenICam name=value, applied after the above, in order
    buffers: int = 16  # buffers queued to the stream: about a quarter second at 60 fps
    silence_s: float = 3.0  # no frame for this long (or control-lost): the camera is gone
    backoff_s: float = 0.5
    max_backoff_s: float = 30.0
    sensor_id: str = "GIGE"


def _ahead(previous: int, current: int, wrap: int) -> int | None:
    """Steps forward from ``previous`` to ``current`` on the ring of ids 1..``wrap`` (0 is never
    used), or None for an id behind ``previous``: a buffer handed over after a newer one (an
    incomplete frame's, completed late), not a wrap. Half the ring tells one from the other; a
    gap of half the ring (9 minutes at 60 fps) is a ``source_gap``, counted by time."""
    step = (current - previous) % wrap
    return step if 0 < step <= wrap // 2 else None


def block_ids_missed(previous: int, current: int, wrap: int = 65535) -> int:
    """Frames between two block ids that never came: none for a late buffer."""
    step = _ahead(previous, current, wrap)
    return step - 1 if step is not None else 0


def newest_block_id(previous: int | None, current: int, wrap: int = 65535) -> int:
    """The id the stream has reached: a late buffer does not take it back."""
    if previous is None or current == previous:
        return current
    return current if _ahead(previous, current, wrap) is not None else previous


def _aravis() -> Any:
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis
    except (ImportError, ValueError) as exc:
        from thermcap.recorder.install_hint import install_command

        raise SourceError(
            f"the gige source needs Aravis 0.8 and PyGObject ({exc}): on Debian or Ubuntu, "
            f"apt-get install gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev pkg-config, then "
            f"{install_command('gige')}") from None
    return Aravis


class _Link:
    """One connection: a camera, its stream and the buffers queued to it. A lost camera needs a
    new one; nothing of an old link is reused."""

    def __init__(self, aravis: Any, options: GigEOptions) -> None:
        self.lost = threading.Event()
        self.camera: Any = None
        self.device: Any = None
        self.stream: Any = None
        self._handler: int | None = None
        try:
            self.camera = aravis.Camera.new(options.camera or None)
        except Exception as exc:  # GLib.Error: no such camera, no answer
            raise SourceError(f"gige:{options.camera}: {_glib_message(exc)}{_found(aravis)}") from None
        try:
            self._open(aravis, options)
        except BaseException:
            # A connection that took the camera's control and then failed must let go of it: GigE
            # Vision gives control to one controller, and a device object kept alive here would
            # go on heartbeating and keep every later connection out.
            self.release()
            raise

    def _open(self, aravis: Any, options: GigEOptions) -> None:
        self.device = self.camera.get_device()
        lost = self.lost  # the handler holds the event alone: a handler holding the link would keep it alive
        self._handler = self.device.connect("control-lost", lambda *_: lost.set())
        try:
            self.camera.set_pixel_format_from_string(options.pixel_format)
            self.camera.set_region(0, 0, options.width, options.height)
            self.camera.set_frame_rate(options.fps)
            if options.features:
                self.device.set_features_from_string(" ".join(f"{k}={v}" for k, v in options.features))
        except Exception as exc:
            raise SourceError(f"gige:{options.camera}: setting the camera: {_glib_message(exc)}") from None
        self.config = _read_config(self.device)
        width, height = self.camera.get_region()[2:]
        pixel_format = self.camera.get_pixel_format_as_string()
        if (width, height) != (options.width, options.height) or pixel_format != options.pixel_format:
            raise SourceError(f"gige:{options.camera}: the camera gives {width}x{height} {pixel_format}, not the "
                              f"{options.width}x{options.height} {options.pixel_format} asked for")
        self.fps = self.camera.get_frame_rate()
        self.payload = self.camera.get_payload()
        self.xml, self.xml_problem = _genicam_xml(self.device)
        self.xml_digest = hashlib.sha256(self.xml).hexdigest() if self.xml else ""  # a different camera: a new one
        self.stream = self.camera.create_stream(None, None)
        if self.stream is None:
            raise SourceError(f"gige:{options.camera}: the camera gave no stream")
        if hasattr(aravis, "GvStreamSocketBuffer"):
            self.stream.set_property("socket-buffer", aravis.GvStreamSocketBuffer.AUTO)
        for _ in range(options.buffers):
            self.stream.push_buffer(aravis.Buffer.new_allocate(self.payload))
        self.camera.start_acquisition()

    def statistics(self) -> dict[str, int]:
        out = {}
        for i in range(self.stream.get_n_infos()):
            name = self.stream.get_info_name(i)
            if name in ("n_completed_buffers", "n_failures", "n_underruns", "n_timeouts", "n_missing_frames",
                        "n_missing_packets", "n_resend_requests", "n_resent_packets", "n_size_mismatch_errors"):
                out[name] = int(self.stream.get_info_uint64(i))
        return out

    def close(self) -> None:
        self.release()

    def release(self) -> None:
        """Stop acquiring and drop every reference to the camera, its device and its stream, so
        Aravis ends the control session (its heartbeat) and the camera takes another controller."""
        if self.camera is not None:
            with contextlib.suppress(Exception):
                self.camera.stop_acquisition()
        if self.device is not None and self._handler is not None:
            with contextlib.suppress(Exception):
                self.device.disconnect(self._handler)
        self.stream = self.device = self.camera = None
        self._handler = None


class GigESource(FrameSource):
    name = "gige"

    def __init__(self, options: GigEOptions, *, model: RadiometricModel = DEFAULT_MODEL) -> None:
        if options.pixel_format not in SIXTEEN_BIT_FORMATS:
            raise SourceError(f"gige:{options.camera}: pixel format {options.pixel_format!r}: thermcap records "
                              f"one uint16 per pixel ({', '.join(SIXTEEN_BIT_FORMATS)})")
        if options.width <= 0 or options.height <= 0 or options.fps <= 0:
            raise SourceError(f"gige:{options.camera}: width, height and fps must be positive")
        self.options = options
        self.model = model
        self.can_wait = False
        self.time_basis = "capture"
        self._aravis = _aravis()
        self._link: _Link | None = _Link(self._aravis, options)  # a camera that is not there fails here
        cfg = self._link.config
        self.sensor = SensorInfo(model=" ".join(str(cfg[k]) for k in ("DeviceVendorName", "DeviceModelName")
                                                if cfg.get(k)) or "GigE Vision camera",
                                 sensor_id=options.sensor_id, serial_number=str(cfg.get("DeviceSerialNumber")
                                                                                or "unknown"),
                                 width=options.width, height=options.height, frame_rate_hz=options.fps,
                                 pixel_pitch_um=None, netd_mk=None)
        self.gaps = GapLog(on_close=self.tell)
        self.reconnects = 0
        self.incomplete: Counter[str] = Counter()  # by Aravis buffer status
        self.frames_missed = 0  # by block id, in the stream and across gaps
        self.configs: list[dict[str, Any]] = [cfg]
        self._xml_digest = self._link.xml_digest  # the first camera's: every segment carries it
        self._first_xml = self._link.xml
        self._xml_problem = self._link.xml_problem
        self._stream_stats: dict[str, int] = {}  # the closed connections' stream counters, summed
        self._wake = threading.Event()

    # -- what it tells ---------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        return {"source": "gige", "camera": self.options.camera, "pixel_format": self.options.pixel_format,
                "width": self.options.width, "height": self.options.height, "fps": self.options.fps,
                "features": dict(self.options.features), "genicam": self.configs[-1],
                "genicam_xml_bytes": len(self._first_xml),  # 0: the camera gave none (said, not hidden)
                **({"genicam_xml_problem": self._xml_problem} if self._xml_problem else {}),
                "time_basis": self.time_basis}

    def health(self) -> dict[str, Any]:
        link = self._link
        return {"connected": link is not None and not link.lost.is_set(), "reconnects": self.reconnects,
                "incomplete_frames": sum(self.incomplete.values()), "incomplete_by_status": dict(self.incomplete),
                "frames_missed": self.frames_missed, **self.gaps.health(),
                "stream": _summed(self._stream_stats, link.statistics() if link is not None else {})}

    def segment_attachments(self) -> list[tuple[str, str, bytes]]:
        """The GenICam XML of the camera as connected, in every segment from its start."""
        link = self._link
        xml = link.xml if link is not None else self._first_xml
        return [("genicam.xml", "application/xml", xml)] if xml else []

    # -- capture ---------------------------------------------------------------------------
    def stop(self) -> None:
        super().stop()
        self._wake.set()

    def close(self) -> None:
        if self._link is not None:
            self._stream_stats = _summed(self._stream_stats, self._link.statistics())  # over every connection
            self._link.close()
            self._link = None

    def frames(self) -> Iterator[CapturedFrame]:
        aravis, opts = self._aravis, self.options
        expected = opts.width * opts.height * 2
        period_us = int(min(max(2.0 / opts.fps, 0.05), 0.5) * 1e6)  # pops wake often enough to see a stop
        index, last_id, last_frame_mono, last_frame_ns = 0, None, time.monotonic(), time.time_ns()
        gap_ids_from: int | None = None
        while not self.stopped:
            link = self._link
            if link is None or link.lost.is_set() or time.monotonic() - last_frame_mono > opts.silence_s:
                why = "control lost" if link is not None and link.lost.is_set() else \
                    f"no frame for {opts.silence_s:g} s" if link is not None else "no camera"
                self.gaps.open(f"gige:{opts.camera}: {why}", start_ns=last_frame_ns, frames_before=index,
                               last_device_frame_id=last_id)
                gap_ids_from = last_id
                if not self._reconnect():
                    break
                last_frame_mono = time.monotonic()
                continue
            buf = link.stream.timeout_pop_buffer(period_us)
            if buf is None:
                continue
            status, frame_id = buf.get_status(), buf.get_frame_id()
            if self.gaps.open_gap is None and last_id is not None and frame_id != last_id:
                self.frames_missed += block_ids_missed(last_id, frame_id)  # ids never seen, whole or not
            if status != aravis.BufferStatus.SUCCESS:
                self.incomplete[status.value_nick] += 1
                link.stream.push_buffer(buf)
                if self.gaps.open_gap is None:
                    last_id = newest_block_id(last_id, frame_id)
                continue
            data = buf.get_data()
            device_ns, host_ns = buf.get_timestamp(), buf.get_system_timestamp()
            link.stream.push_buffer(buf)
            if len(data) != expected:
                self.incomplete["size-mismatch"] += 1
                last_id = newest_block_id(last_id, frame_id) if self.gaps.open_gap is None else last_id
                continue
            now = last_frame_ns = time.time_ns()
            last_frame_mono = time.monotonic()
            if self.gaps.open_gap is not None:
                self._close_gap(now, gap_ids_from, frame_id)
                last_id = frame_id  # a camera that restarted numbers afresh: its ids from here on
            else:
                last_id = newest_block_id(last_id, frame_id)
            pixels = np.frombuffer(data, dtype="<u2").reshape(opts.height, opts.width)
            frame = CapturedFrame(index=index, timestamp_ns=host_ns or now, pixels=pixels,
                                  capture_mono_ns=time.monotonic_ns(),
                                  sidecar={"capture": {"device_timestamp_ns": int(device_ns),
                                                       "device_frame_id": int(frame_id)}})
            if link.xml_digest != self._xml_digest:  # a different camera after a gap: its XML with its frames
                self._xml_digest = link.xml_digest
                if index:
                    frame.attachments.append((f"genicam-{index}.xml", "application/xml", link.xml))
            index += 1
            yield frame
        if self.gaps.open_gap is not None:
            self.gaps.close(reason=self.gaps.open_gap["reason"] + "; no frame came before the stop",
                            reconnects=self.reconnects)

    def _reconnect(self) -> bool:
        """A new camera and stream with every setting applied again; False when stopped first."""
        opts = self.options
        self.close()
        delay = opts.backoff_s
        attempts = 0
        while not self.stopped:
            self._wake.wait(delay)
            if self.stopped:
                return False
            attempts += 1
            try:
                link = _Link(self._aravis, opts)
            except SourceError as exc:
                self.gaps.open_gap["last_error"] = str(exc)  # type: ignore[index]
                delay = min(delay * 2, opts.max_backoff_s)
                continue
            self._link = link
            self.reconnects += 1
            self.gaps.open_gap["attempts"] = attempts  # type: ignore[index]
            if link.config != self.configs[-1]:
                self.configs.append(link.config)
            return True
        return False

    def _close_gap(self, now: int, ids_from: int | None, frame_id: int) -> None:
        gap = self.gaps.open_gap
        assert gap is not None
        by_time = max(0, round((now - gap["start_ns"]) / 1e9 * self.options.fps) - 1)
        ahead = _ahead(ids_from, frame_id, 65535) if ids_from is not None else None
        by_id = ahead - 1 if ahead is not None else None  # ids behind: a camera that began again
        # a camera that ran on keeps counting; one that restarted begins again: trust its ids only
        # where they agree with the time that passed
        trusted = by_id is not None and by_id <= 2 * by_time + 2 * self.options.fps
        missed = by_id if trusted and by_id is not None else by_time
        self.frames_missed += missed
        self.gaps.close(now, frames_missed=missed, frames_missed_from="device_frame_id" if trusted else "time",
                        device_frame_id=frame_id, reconnects=self.reconnects, genicam=self.configs[-1])


def _summed(a: dict[str, int], b: dict[str, int]) -> dict[str, int]:
    return {k: a.get(k, 0) + b.get(k, 0) for k in {**a, **b}}


def _read_config(device: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in _CONFIG_FEATURES:
        node = device.get_feature(name)
        if node is None:
            continue
        try:
            out[name] = node.get_value_as_string()
        except Exception:
            continue
    return out


def _genicam_xml(device: Any) -> tuple[bytes, str]:
    """The camera's GenICam XML, exactly its ``size`` bytes, and why not where it has none to
    give (said in ``describe()``). PyGObject reads ``arv_device_get_genicam_xml``'s result as a
    NUL-terminated string, but a GigE device's downloaded XML is not terminated: the string ran
    on into whatever followed it in memory (a decode error, or garbage after the XML). The bytes
    are taken by the size Aravis gives, through its C function."""
    try:
        return _xml_by_size(device), ""
    except Exception as exc:  # no libaravis to load by name: PyGObject's string, checked below
        why = f"{type(exc).__name__}: {exc}"
    try:
        text, size = device.get_genicam_xml()
    except Exception as exc:
        return b"", f"{why}; {type(exc).__name__}: {_glib_message(exc)}"
    data = (text or "").encode()
    if len(data) != size:
        return b"", f"{why}; PyGObject gave {len(data)} bytes of the {size} the camera's XML holds"
    return data, "" if data else "the camera gave none"


def _xml_by_size(device: Any) -> bytes:
    import ctypes
    import ctypes.util

    lib = ctypes.CDLL(ctypes.util.find_library("aravis-0.8") or "libaravis-0.8.so.0")
    get_xml = lib.arv_device_get_genicam_xml
    get_xml.restype = ctypes.c_void_p
    get_xml.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_size_t)]
    pointer_of = ctypes.pythonapi.PyCapsule_GetPointer
    pointer_of.restype = ctypes.c_void_p
    pointer_of.argtypes = [ctypes.py_object, ctypes.c_char_p]
    size = ctypes.c_size_t(0)
    at = get_xml(pointer_of(device.__gpointer__, None), ctypes.byref(size))
    if not at:
        raise SourceError("the camera gave no GenICam XML")
    return ctypes.string_at(at, size.value)


def _found(aravis: Any) -> str:
    try:
        aravis.update_device_list()
        found = [f"{aravis.get_device_id(i)} ({aravis.get_device_address(i)})"
                 for i in range(aravis.get_n_devices())]
    except Exception:
        return ""
    return f"; cameras found: {', '.join(found)}" if found else "; no camera found"


def _glib_message(exc: BaseException) -> str:
    return str(getattr(exc, "message", None) or exc)


def _from_settings(camera: str, s: CameraSettings) -> GigESource:
    own = dict(s.own)
    pixel_format = own.pop("PixelFormat", "Mono16")
    try:  # a triggered camera may be silent for long: how long before it counts as gone
        silence = float(own.pop("silence", 3.0))
    except ValueError:
        raise SourceError(f"gige:{camera}: silence must be seconds, got {s.own.get('silence')!r}") from None
    if not 0.1 <= silence <= 86_400:
        raise SourceError(f"gige:{camera}: silence must be between 0.1 and 86400 s, got {silence:g}")
    return GigESource(GigEOptions(camera=camera, width=s.width, height=s.height, fps=s.fps, pixel_format=pixel_format,
                                  features=tuple(own.items()), sensor_id=s.sensor_id or "GIGE", silence_s=silence))


register_source(SourceKind("gige", "gige:CAMERA (an address or name; gige: for the first found)", _from_settings,
                           own_key=lambda key: key[:1].isupper() or key == "silence", target_optional=True))
