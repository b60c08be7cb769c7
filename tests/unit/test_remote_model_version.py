"""A remote session's Dataset names one model version only where the server's store really uses
it for every frame (the latest version, covering the whole session)."""

from __future__ import annotations

import pytest

from thermcap.recorder.radiometry.params import ModelVersion
from thermcap.remote import RemoteSession


class _Versions:
    """Only what to_xarray asks before opening the store: the session's model versions."""

    def __init__(self, versions):
        self._versions = versions

    def model_versions(self, session_id):
        return self._versions


def _v(n, frames=None):
    return ModelVersion(n, "2026-12-03T00:00:00Z", "me", "why", {"emissivity": 0.9}, frames)


@pytest.mark.parametrize("versions,asked", [
    ([], 1),                              # no such version
    ([_v(1), _v(2)], 1),                  # not the latest
    ([_v(1), _v(2, (0, 10))], 2),         # the latest covers only frames 0..9: others use version 1
])
def test_a_version_the_store_does_not_use_throughout_is_refused(versions, asked):
    session = RemoteSession(_Versions(versions), "s")
    with pytest.raises(ValueError, match=f"model version {asked}"):
        session.to_xarray(model_version=asked)
