"""nginx as the benchmark's anchor: the same bytes served as static files, to the same client.

nginx is what "static-file speed" means in practice (sendfile, no framework), so the frame and
export figures are ratios against it, measured in the same run. It is found on PATH or in
/usr/sbin (Debian's ``nginx-light``); where it is missing the bench says so and gives no ratio.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

__all__ = ["Nginx", "find_nginx"]


def find_nginx() -> str | None:
    return shutil.which("nginx") or next((p for p in ("/usr/sbin/nginx", "/usr/local/sbin/nginx")
                                          if os.access(p, os.X_OK)), None)


class Nginx:
    """``nginx`` in the foreground on 127.0.0.1, serving ``docroot``; one worker, as one uvicorn."""

    def __init__(self, docroot: Path, workdir: Path) -> None:
        exe = find_nginx()
        if exe is None:
            raise FileNotFoundError("nginx is not installed (Debian: apt-get install nginx-light)")
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        workdir.mkdir(parents=True, exist_ok=True)
        temp = {k: workdir / k for k in ("body", "proxy", "fastcgi", "uwsgi", "scgi")}
        user = "user root;" if os.geteuid() == 0 else ""  # workers read the bench's private temp folder
        conf = workdir / "nginx.conf"
        conf.write_text(f"""{user}
daemon off; worker_processes 1; pid {workdir}/nginx.pid; error_log {workdir}/error.log warn;
events {{ worker_connections 256; }}
http {{
  access_log off; sendfile on; tcp_nopush on; tcp_nodelay on; keepalive_requests 1000000;
  types {{ image/png png; application/octet-stream raw mcap; }}
  client_body_temp_path {temp['body']}; proxy_temp_path {temp['proxy']}; fastcgi_temp_path {temp['fastcgi']};
  uwsgi_temp_path {temp['uwsgi']}; scgi_temp_path {temp['scgi']};
  server {{ listen 127.0.0.1:{self.port}; root {docroot}; }}
}}
""")
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen([exe, "-c", str(conf), "-p", str(workdir)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                if self.proc.poll() is not None:
                    break
                time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"nginx did not start (see {workdir / 'error.log'})")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
