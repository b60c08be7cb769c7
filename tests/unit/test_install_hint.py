"""A hint to install an extra names the form that works for how thermcap was installed:
``pip install 'thermcap[maps]'`` fails where thermcap came from a checkout (no index holds it)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from thermcap.recorder import install_hint
from thermcap.recorder.install_hint import install_command


class _Dist:
    def __init__(self, direct: dict | None) -> None:
        self.direct = direct

    def read_text(self, name: str) -> str | None:
        return json.dumps(self.direct) if name == "direct_url.json" and self.direct is not None else None


def _installed(monkeypatch, direct: dict | None) -> None:
    monkeypatch.setattr(install_hint, "_checkout", lambda: None)
    monkeypatch.setattr(install_hint.metadata, "distribution", lambda name: _Dist(direct))


def test_running_from_a_checkout_names_the_checkout(monkeypatch, tmp_path):
    monkeypatch.setattr(install_hint, "_checkout", lambda: tmp_path.resolve())
    monkeypatch.chdir(tmp_path)
    assert install_command("maps") == "pip install -e '.[maps]'"
    monkeypatch.chdir(Path("/"))
    assert install_command("server,python") == f"pip install -e '{tmp_path.resolve()}[server,python]'"


def test_a_copy_from_an_index_names_the_package(monkeypatch):
    _installed(monkeypatch, None)
    assert install_command("fleet") == "pip install 'thermcap[fleet]'"


@pytest.mark.parametrize("direct,want", [
    ({"url": "file:///opt/thermcap-0.1.0-py3-none-any.whl", "archive_info": {}},
     "pip install '/opt/thermcap-0.1.0-py3-none-any.whl[maps]'"),
    ({"url": "file:///src/thermcap", "dir_info": {"editable": True}}, "pip install -e '/src/thermcap[maps]'"),
    ({"url": "file:///src/my%20thermcap", "dir_info": {}}, "pip install '/src/my thermcap[maps]'"),
    ({"url": "https://example.invalid/thermcap.whl", "archive_info": {}}, "pip install 'thermcap[maps]'"),
])
def test_a_copy_from_a_path_names_the_path(monkeypatch, direct, want):
    _installed(monkeypatch, direct)
    assert install_command("maps") == want


def test_this_checkout_is_found():
    assert install_hint._checkout() == Path(__file__).resolve().parents[2]
