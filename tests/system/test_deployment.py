"""The deployment files, run rather than read: docker-compose.yml's own commands and environment
drive a real recorder, archiver worker and API against PostgreSQL and SeaweedFS on 127.0.0.1, and
the Dockerfile's build context installs a complete ``thermcap``.

Docker is not needed: what Docker adds (DNS names for the services) is mapped to the local
processes, and everything else (commands, variables, defaults, tokens, health checks) is taken from
the files as written, so a broken command or a missing variable in them fails here.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.conftest import free_port, wait_for, wait_http
from thermcap.recorder.storage.reader import iter_session_frames

yaml = pytest.importorskip("yaml")
ROOT = Path(__file__).resolve().parents[2]
_VAR = re.compile(r"\$\{(\w+)(?:(:-|:\?)([^}]*))?\}")


def _env_file(path: Path) -> dict[str, str]:
    out = {}
    for line in path.read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            k, _, v = line.partition("=")
            out[k.strip()] = v.strip()
    return out


def _expand(value: str, env: dict[str, str]) -> str:
    """Compose's interpolation: ${VAR}, ${VAR:-default}, ${VAR:?error}, and $$ for a literal $."""

    def sub(m: re.Match[str]) -> str:
        name, op, arg = m.group(1), m.group(2), m.group(3)
        if env.get(name):
            return env[name]
        if op == ":?":
            raise AssertionError(f"docker-compose.yml needs {name} ({arg}) and .env.example does not set it")
        return arg if op == ":-" else ""

    return _VAR.sub(sub, value.replace("$$", "\0")).replace("\0", "$")


class Compose:
    """docker-compose.yml with .env.example's values, and the service names Docker's DNS would
    resolve mapped to local processes."""

    def __init__(self, hosts: dict[str, str], overrides: dict[str, str]) -> None:
        self.doc = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
        self.vars = {**_env_file(ROOT / ".env.example"), **overrides}
        self.hosts = hosts

    def _resolve(self, value: str) -> str:
        value = _expand(str(value), self.vars)
        for name, local in self.hosts.items():
            value = value.replace(name, local)
        return value

    def command(self, service: str) -> list[str]:
        return [self._resolve(a) for a in self.doc["services"][service]["command"]]

    def environment(self, service: str) -> dict[str, str]:
        return {k: self._resolve(v) for k, v in self.doc["services"][service]["environment"].items()}


def _replace_option(cmd: list[str], option: str, value: str) -> list[str]:
    i = cmd.index(option)
    return [*cmd[:i + 1], value, *cmd[i + 2:]]


def _thermcap(cmd: list[str], env: dict[str, str], **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "thermcap", *cmd], env={**os.environ, **env}, **kw)


def _stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> None:
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _compose_database(postgres_url: str, user: str, password: str, db: str) -> str:
    """The role and database compose's postgres service creates from POSTGRES_USER/PASSWORD/DB."""
    from sqlalchemy import create_engine, text

    engine = create_engine(postgres_url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        if not conn.execute(text("SELECT 1 FROM pg_roles WHERE rolname = :u"), {"u": user}).first():
            conn.execute(text(f"CREATE ROLE \"{user}\" LOGIN PASSWORD '{password}'"))
        if not conn.execute(text("SELECT 1 FROM pg_database WHERE datname = :d"), {"d": db}).first():
            conn.execute(text(f'CREATE DATABASE "{db}" OWNER "{user}"'))
    engine.dispose()
    return postgres_url.split("@", 1)[1].split("/", 1)[0]  # host:port


def test_compose_services_run_as_written(postgres_url, seaweedfs, tmp_path):
    example = _env_file(ROOT / ".env.example")
    pg_hostport = _compose_database(postgres_url, example["POSTGRES_USER"], example["POSTGRES_PASSWORD"],
                                    example.get("POSTGRES_DB", "thermcap"))
    # SeaweedFS takes its S3 user from the same two variables compose gives both it and thermcap.
    creds = {k: seaweedfs[k] for k in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY")}
    # a token of the user's own, as the example asks (its placeholder is refused as a token)
    compose = Compose({"postgres:5432": pg_hostport, "http://seaweedfs:8333": seaweedfs["endpoint"]},
                      {**creds, "THERMCAP_S3_BUCKET": seaweedfs["bucket"],
                       "THERMCAP_TOKENS": "compose-deployment-token-0123456789=read,write"})
    data = tmp_path / "data"
    local = {"THERMCAP_ROOT": str(data), "THERMCAP_S3_PREFIX": f"compose-{tmp_path.name}"}

    rec = _thermcap(compose.command("recorder"), {**compose.environment("recorder"), **local},
                    stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    sessions = data / "sessions"
    try:
        assert wait_for(lambda: any(sessions.glob("*/*.mcap.active")), 60), "the recorder never started a segment"
        time.sleep(1.5)
    finally:
        _stop(rec, signal.SIGINT)  # what `docker compose stop` sends is SIGTERM; SIGINT is the user's Ctrl-C
    assert rec.returncode == 0, rec.stderr.read().decode()[-2000:] if rec.stderr else ""
    (session,) = sessions.iterdir()
    recorded = [f.pixels.copy() for f in iter_session_frames(session)]
    assert len(recorded) > 30

    worker = _thermcap(compose.command("archiver"), {**compose.environment("archiver"), **local},
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    manifest = session / "archive" / "manifest.json"
    try:
        assert wait_for(lambda: manifest.is_file() and '"complete": true' in manifest.read_text(), 240), \
            "the archiver did not archive and upload the session"
    finally:
        _stop(worker)

    port = free_port()
    api_cmd = _replace_option(_replace_option(compose.command("api"), "--host", "127.0.0.1"), "--port", str(port))
    api = _thermcap(api_cmd, {**compose.environment("api"), **local}, stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE)
    try:
        wait_http(f"http://127.0.0.1:{port}/healthz")
        health = [a.replace(":8000/", f":{port}/") for a in compose.doc["services"]["api"]["healthcheck"]["test"]]
        assert health[0] == "CMD"
        assert subprocess.run(health[1:], timeout=30).returncode == 0, "compose's own health check fails"
        token = compose.vars["THERMCAP_TOKENS"].split(";")[0].split("=")[0]
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30) as c:
            assert c.get("/api/v1/sessions").status_code == 401  # tokens are set: nothing is open
            auth = {"Authorization": f"Bearer {token}"}
            items = c.get("/api/v1/sessions", headers=auth).json()["items"]
            assert [s["id"] for s in items] == [session.name]
            n = len(recorded) // 2
            raw = c.get(f"/api/v1/sessions/{session.name}/frames/{n}", params={"format": "raw"}, headers=auth)
            assert raw.status_code == 200
            assert np.array_equal(np.frombuffer(raw.content, "<u2").reshape(recorded[n].shape), recorded[n])
    finally:
        _stop(api)


def test_compose_has_no_secrets_and_env_example_names_them():
    text = (ROOT / "docker-compose.yml").read_text()
    for line in text.splitlines():
        if re.search(r"(PASSWORD|SECRET|TOKENS?)\s*:", line):
            assert "${" in line, f"a literal secret in docker-compose.yml: {line.strip()}"
    example = _env_file(ROOT / ".env.example")
    for var in ("POSTGRES_PASSWORD", "AWS_SECRET_ACCESS_KEY", "THERMCAP_TOKENS"):
        assert var in example


def test_dockerfile_context_installs_every_command(tmp_path):
    """What the Dockerfile COPYs is enough for `pip install .` to give the whole CLI."""
    context = tmp_path / "context"
    context.mkdir()
    copies = re.findall(r"^COPY\s+(.+?)\s+(\S+)\s*$", (ROOT / "Dockerfile").read_text(), re.M)
    assert copies
    for sources, dest in copies:
        for src in sources.split():
            target = context / dest if dest not in ("./", ".") else context
            if (ROOT / src).is_dir():
                shutil.copytree(ROOT / src, context / dest, ignore=shutil.ignore_patterns("__pycache__"))
            else:
                shutil.copy2(ROOT / src, target)
    site = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--quiet", "--target", str(site),
                        str(context)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = subprocess.run([sys.executable, "-c", "from importlib.metadata import entry_points;"
                          "import thermcap.recorder as r, thermcap.archive as a, thermcap.api as p;"
                          "print(r.__file__, a.__file__, p.__file__);"
                          "print([e.value for e in entry_points(group='console_scripts', name='thermcap')])"],
                         capture_output=True, text=True, cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr
    assert all(p.startswith(str(site)) for p in out.stdout.split("\n")[0].split())  # the installed copy, not ours
    helped = subprocess.run([sys.executable, "-m", "thermcap", "--help"], capture_output=True, text=True,
                            cwd=tmp_path, env=env)
    assert helped.returncode == 0, helped.stderr
    for command in ("record", "archive", "verify", "serve", "worker", "scrub", "gc"):
        assert re.search(rf"^\s+{command}\s", helped.stdout, re.M), f"`thermcap {command}` missing from the image"
    text = (ROOT / "Dockerfile").read_text()
    assert re.search(r"^USER (?!root)\S+", text, re.M), "the image must not run as root"
