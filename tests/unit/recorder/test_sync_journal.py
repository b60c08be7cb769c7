"""sync's journal on a vehicle that records for hours: what one part costs to journal must not
grow with every object ever shipped (the hour-long soak fell 1,214 segments behind when it did),
and what was journaled survives a crash, a torn last line and the format before it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.sync_journal import Journal, ObjectState, PartState


def _written_bytes() -> int:
    """Bytes this process has handed to write(2): what a journal update costs the disk,
    whatever the journal's layout."""
    for line in Path("/proc/self/io").read_text().splitlines():
        if line.startswith("wchar:"):
            return int(line.split()[1])
    raise AssertionError("no wchar in /proc/self/io")


def _shipped(n: int) -> dict[str, dict]:
    """``n`` segments the cloud confirmed, as a long recording leaves them: most freed since."""
    return {f"sessions/s/{i:06d}.mcap": {
        "key": f"sessions/s/{i:06d}.mcap", "size": 30 << 20, "sha256": f"{i:064x}", "mtime_ns": i,
        "state": "confirmed", "upload_id": None, "part_size": 8 << 20, "attempts": 4, "error": None,
        "stale_receipt": None,
        "parts": [{"number": p, "size": 8 << 20, "etag": f"e{p}", "sha256": f"{p:064x}"} for p in range(1, 5)],
    } for i in range(n)}


def _journal_of(root: Path, objects: dict[str, dict]) -> None:
    """A journal as the format before this one wrote it: every object in one JSON file."""
    (root / ".sync").mkdir(parents=True)
    (root / ".sync" / "journal.json").write_text(json.dumps({"version": 1, "objects": objects}))


@pytest.mark.skipif(not Path("/proc/self/io").is_file(), reason="needs Linux's /proc/self/io to count bytes written")
def test_a_part_costs_the_same_to_journal_after_thousands_of_objects(tmp_path):
    root = tmp_path / "vehicle"
    _journal_of(root, _shipped(5000))
    j = Journal(root)
    assert len(j.objects) == 5000
    st = ObjectState("sessions/s/new.mcap", 30 << 20, "ab" * 32, 1, state="in_flight", upload_id="u", part_size=8 << 20)
    before = _written_bytes()
    for n in range(1, 41):
        st.parts.append(PartState(n, 8 << 20, f"e{n}", f"{n:064x}"))
        j.put(st)
    per_part = (_written_bytes() - before) / 40
    # the object's own state (its parts so far), not the other 5,000 objects' (2.5 MB each time)
    assert per_part < 16_000, f"{per_part:.0f} bytes written per part journaled"
    again = Journal(root)
    assert len(again.objects["sessions/s/new.mcap"].parts) == 40 and len(again.objects) == 5001


def test_objects_shipped_and_gone_from_the_vehicle_leave_memory_but_not_the_record(tmp_path):
    root = tmp_path / "vehicle"
    _journal_of(root, _shipped(3000))
    here = root / "sessions" / "s" / "000007.mcap"
    here.parent.mkdir(parents=True)
    here.write_bytes(b"x")
    j = Journal(root)
    j.compact()
    assert list(j.objects) == ["sessions/s/000007.mcap"]  # the one still on the vehicle
    assert len({k for k, _ in j.finished()}) == 2999
    assert len(Journal(root).objects) == 1


def test_a_torn_last_line_costs_only_that_update(tmp_path):
    root = tmp_path / "vehicle"
    j = Journal(root)
    st = ObjectState("sessions/s/a.mcap", 10, "cd" * 32, 1, state="in_flight", upload_id="u", part_size=5)
    for n in (1, 2):
        st.parts.append(PartState(n, 5, f"e{n}", "0" * 64))
        j.put(st)
    log = j.log_path
    with open(log, "ab") as f:  # the power went while the third part's line was written
        f.write(b'{"put": {"key": "sessions/s/a.mc')
    again = Journal(root)
    assert [p.number for p in again.objects["sessions/s/a.mcap"].parts] == [1, 2]
    st2 = again.objects["sessions/s/a.mcap"]
    st2.parts.append(PartState(3, 5, "e3", "0" * 64))
    again.put(st2)  # appended after the torn line is cut away, not glued to it
    assert [p.number for p in Journal(root).objects["sessions/s/a.mcap"].parts] == [1, 2, 3]


def test_damage_inside_the_journal_is_named_not_guessed_past(tmp_path):
    root = tmp_path / "vehicle"
    j = Journal(root)
    for k in "abc":
        j.put(ObjectState(f"sessions/s/{k}.mcap", 1, "0" * 64, 1))
    lines = j.log_path.read_bytes().splitlines(keepends=True)
    j.log_path.write_bytes(lines[0] + b"garbage\n" + b"".join(lines[1:]))
    with pytest.raises(ThermcapError, match="journal"):
        Journal(root)


def test_reading_the_journal_changes_nothing(tmp_path):
    """The ring reads it to learn what the cloud confirmed while sync writes it."""
    root = tmp_path / "vehicle"
    _journal_of(root, _shipped(3))
    before = sorted((p.name, p.read_bytes()) for p in (root / ".sync").iterdir())
    assert len(Journal(root, read_only=True).objects) == 3
    assert sorted((p.name, p.read_bytes()) for p in (root / ".sync").iterdir()) == before


def test_status_still_names_what_left_memory(tmp_path):
    """A segment the ring evicted after it was sent, and one freed after the cloud confirmed it,
    stay in ``sync --status`` once the journal has moved them out of memory."""
    from thermcap.recorder.sync.engine import Syncer
    from thermcap.recorder.sync.targets import DirTarget

    root = tmp_path / "vehicle"
    objects = _shipped(2)
    objects["sessions/s/000001.mcap"]["state"] = "uploaded"  # evicted before its receipt came
    _journal_of(root, objects)
    (root / "sessions" / "s").mkdir(parents=True)
    j = Journal(root)
    j.compact()
    assert not j.objects
    st = Syncer(root, DirTarget(tmp_path / "depot")).status()
    assert st.confirmed == ["sessions/s/000000.mcap"] and st.uploaded == ["sessions/s/000001.mcap"]
