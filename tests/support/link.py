"""A flaky, throttled link on 127.0.0.1 for sync tests: a TCP proxy to a real server that sends
at most ``rate`` bytes a second towards it and cuts every connection open when another
``cut_every`` bytes have gone through. It counts what it carried and how often it cut."""

from __future__ import annotations

import contextlib
import socket
import threading
import time


class FlakyLink:
    def __init__(self, upstream: tuple[str, int], *, rate: float, cut_every: int) -> None:
        self.upstream, self.rate, self.cut_every = upstream, rate, cut_every
        self.sent = 0  # bytes towards the server
        self.cuts = 0
        self._next_cut = cut_every
        self._lock = threading.Lock()
        self._conns: list[socket.socket] = []
        self._srv = socket.create_server(("127.0.0.1", 0))
        self.port = self._srv.getsockname()[1]
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        threading.Thread(target=self._accept, daemon=True).start()

    @property
    def endpoint(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._srv.accept()
            except OSError:
                return
            try:
                server = socket.create_connection(self.upstream)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._conns += [client, server]
            threading.Thread(target=self._pump, args=(client, server, True), daemon=True).start()
            threading.Thread(target=self._pump, args=(server, client, False), daemon=True).start()

    def _cut_all(self) -> None:
        self.cuts += 1
        for s in self._conns:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()
        self._conns.clear()

    def _pump(self, src: socket.socket, dst: socket.socket, upstream: bool) -> None:
        try:
            while True:
                data = src.recv(16384)
                if not data:
                    break
                if upstream:
                    with self._lock:
                        self.sent += len(data)
                        due = self._t0 + self.sent / self.rate
                        cut = self.sent >= self._next_cut
                        if cut:
                            self._next_cut += self.cut_every
                    wait = due - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                    if cut:
                        with self._lock:
                            self._cut_all()
                        return
                dst.sendall(data)
        except OSError:
            pass
        finally:
            for s in (src, dst):
                with contextlib.suppress(OSError):
                    s.close()

    def close(self) -> None:
        self._stop.set()
        self._srv.close()
        with self._lock:
            self._cut_all()
