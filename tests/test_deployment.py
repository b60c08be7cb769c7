"""docker-compose.yml: the topology the issue asks for, no secrets, API on localhost."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml")
ROOT = Path(__file__).resolve().parents[1]


def test_compose_topology():
    doc = yaml.safe_load((ROOT / "docker-compose.yml").read_text())
    services = doc["services"]
    assert set(services) == {"api", "archiver", "recorder", "postgres", "seaweedfs"}
    for name in ("postgres", "seaweedfs", "api"):
        assert "healthcheck" in services[name], name
    assert set(doc["volumes"]) == {"pgdata", "objects", "sessions"}
    assert services["api"]["ports"] == ["${THERMCAP_API_BIND:-127.0.0.1:8000}:8000"]
    assert services["archiver"]["command"][0] == "worker"
    assert services["api"]["depends_on"]["postgres"]["condition"] == "service_healthy"


def test_compose_has_no_secrets_and_env_example_names_them():
    text = (ROOT / "docker-compose.yml").read_text()
    for line in text.splitlines():
        if re.search(r"(PASSWORD|SECRET|TOKENS?)\s*:", line):
            assert "${" in line, f"a literal secret in docker-compose.yml: {line.strip()}"
    example = (ROOT / ".env.example").read_text()
    for var in ("POSTGRES_PASSWORD", "AWS_SECRET_ACCESS_KEY", "THERMCAP_TOKENS"):
        assert f"{var}=" in example


def test_docker_compose_config_where_the_cli_exists(tmp_path):
    docker = shutil.which("docker")
    if not docker or subprocess.run([docker, "compose", "version"], capture_output=True).returncode != 0:
        pytest.skip("no Docker Compose CLI on this machine")
    r = subprocess.run([docker, "compose", "--env-file", str(ROOT / ".env.example"), "-f",
                        str(ROOT / "docker-compose.yml"),
                        "config", "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_dockerfile_installs_the_package_and_runs_unprivileged():
    text = (ROOT / "Dockerfile").read_text()
    assert "pip install ." in text
    assert "USER thermcap" in text
    assert 'ENTRYPOINT ["thermcap"]' in text
