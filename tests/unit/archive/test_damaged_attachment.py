"""A byte flipped inside a segment's attachment (the bad-pixel map every recording carries): the
archiver refuses by name, as for any damage it cannot carry over, and deletes nothing. Found by
the random journeys' long form: ``archive`` raised mcap's bare ``EndOfFile`` from the extras'
attachment read, a traceback at the command line."""

from __future__ import annotations

import pytest
from mcap.reader import make_reader

from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import McapFileError


@pytest.mark.parametrize("into", [0, 8, 69])  # the record's opcode, its length, inside its name
def test_a_damaged_attachment_is_named_not_a_traceback(tmp_path, into):
    Recorder(SimSource(width=32, height=24, frames=20, paced=False, seed=1), tmp_path, session_id="s",
             analysis=False).run()
    session = tmp_path / "sessions" / "s"
    (seg,) = sorted(session.glob("*.mcap"))
    with open(seg, "rb") as f:
        (att,) = make_reader(f).get_summary().attachment_indexes
    data = bytearray(seg.read_bytes())
    data[att.offset + into] ^= 0x80
    seg.write_bytes(bytes(data))
    before = seg.read_bytes()
    with pytest.raises(McapFileError, match=seg.name):
        archive_session(session, ["png16"], delete_source=True)
    assert seg.read_bytes() == before  # nothing stored is lost or changed
