"""``read_versions`` is asked on every Zarr key and frame a server answers: an unchanged
``radiometry.json`` is not read again, and a new version is seen at once."""

from __future__ import annotations

from pathlib import Path

from thermcap.recorder.radiometry.params import add_version, read_versions
from thermcap.recorder.radiometry.planck import FlirPlanckModel

MODEL = FlirPlanckModel(planck_r1=21106.77, planck_b=1501.0, planck_f=1.0, planck_o=-7340.0, planck_r2=0.012545258)


def test_unchanged_file_is_parsed_once_and_a_new_version_is_seen(tmp_path, monkeypatch):
    session = tmp_path / "s"
    session.mkdir()
    assert read_versions(session) == []
    add_version(session, MODEL, {"emissivity": 0.9}, who="t", why="first")
    reads = []
    real = Path.read_text

    def counting(self: Path, *a, **k):
        reads.append(self.name)
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "read_text", counting)
    assert [v.version for v in read_versions(session)] == [1]
    for _ in range(50):
        assert [v.version for v in read_versions(session)] == [1]
    assert reads.count("radiometry.json") <= 1
    add_version(session, MODEL, {"emissivity": 0.8}, who="t", why="second")
    assert [v.version for v in read_versions(session)] == [1, 2]  # the replaced file, read at once
    (session / "radiometry.json").unlink()
    assert read_versions(session) == []
