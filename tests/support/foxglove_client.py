"""A small client of the Foxglove WebSocket protocol, written from the spec, not from our code.

It connects with the protocol's subprotocol, reads ``serverInfo`` and ``advertise``, subscribes
by topic, and decodes binary ``messageData`` frames (opcode 1: subscription id u32, log time
u64, payload). Protobuf payloads are decoded with the schema the server advertised (a
FileDescriptorSet), as Foxglove itself does, so a test passes only if any client could read it.
"""

from __future__ import annotations

import base64
import contextlib
import json
import struct
import time
from dataclasses import dataclass, field
from typing import Any

from websockets.sync.client import connect

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


@dataclass
class Received:
    topic: str
    log_time: int
    payload: bytes

    def json(self) -> Any:
        return json.loads(self.payload)


@dataclass
class FoxgloveClient:
    url: str
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)  # topic -> advertised channel
    server_info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # entered as the context manager websockets asks for (17 deprecates using it bare)
        self._stack = contextlib.ExitStack()
        self._ws = self._stack.enter_context(connect(self.url, subprotocols=SUBPROTOCOLS, max_size=None,
                                                     open_timeout=10))
        self._subs: dict[int, str] = {}
        self._classes: dict[str, Any] = {}

    def close(self) -> None:
        self._stack.close()

    def _handle_text(self, text: str) -> None:
        msg = json.loads(text)
        if msg.get("op") == "serverInfo":
            self.server_info = msg
        elif msg.get("op") == "advertise":
            for ch in msg["channels"]:
                self.channels[ch["topic"]] = ch

    def wait_for_topics(self, topics: list[str], timeout: float = 15.0) -> None:
        deadline = time.monotonic() + timeout
        while not all(t in self.channels for t in topics):
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"not advertised: {sorted(set(topics) - set(self.channels))}; "
                                   f"advertised: {sorted(self.channels)}")
            try:
                m = self._ws.recv(timeout=left)
            except TimeoutError:
                continue
            if isinstance(m, str):
                self._handle_text(m)

    def subscribe(self, topics: list[str]) -> None:
        self.wait_for_topics(topics)
        subs = []
        for t in topics:
            sid = len(self._subs) + 1
            self._subs[sid] = t
            subs.append({"id": sid, "channelId": self.channels[t]["id"]})
        self._ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def receive(self, count: int, timeout: float = 30.0, topic: str | None = None) -> list[Received]:
        """Up to ``count`` messages (of ``topic``, if given) within ``timeout``."""
        out: list[Received] = []
        deadline = time.monotonic() + timeout
        while len(out) < count:
            left = deadline - time.monotonic()
            if left <= 0:
                break
            try:
                m = self._ws.recv(timeout=left)
            except TimeoutError:
                break
            except Exception:  # the server went away (a replay that ended)
                break
            if isinstance(m, str):
                self._handle_text(m)
                continue
            if m[0] != 0x01:
                continue
            sid, log_time = struct.unpack_from("<IQ", m, 1)
            rec = Received(self._subs.get(sid, "?"), log_time, bytes(m[13:]))
            if topic is None or rec.topic == topic:
                out.append(rec)
        return out

    def decode(self, rec: Received) -> Any:
        """A protobuf message, through the advertised FileDescriptorSet."""
        ch = self.channels[rec.topic]
        if ch["encoding"] == "json":
            return rec.json()
        cls = self._classes.get(rec.topic)
        if cls is None:
            from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

            fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
            pool = descriptor_pool.DescriptorPool()
            for fd in fds.file:
                pool.Add(fd)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))
            self._classes[rec.topic] = cls
        return cls.FromString(rec.payload)
