"""One reader of verified copies: every module that takes a frame out of a copy (a format's
``read_frame``, an MCAP segment's ``McapFrames.frame``) hands it to ``read_verified``
(``archive/reading/copies.py``), which checks it against the manifest and reports damage. A new
path that reads frames without it fails here, naming the module.

The two named exceptions check what they read against the same manifest by a cheaper proof, and
hand anything that does not match to the checked path instead of answering."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ROOMS = ("recorder", "archive", "api", "thermcap")
READS_A_COPY = re.compile(r"\.read_frame\(|\bmcap\.frame\(|_mcap\.frame\(")
CHECKED = re.compile(r"\bread_verified\(")

#: module -> why it may read a copy without ``read_verified``
EXCEPTIONS = {
    # the lean path for png16/raw: checks each frame against the archive's frame summary (band
    # CRCs bound to the manifest) or the frame's digest, and on any mismatch or doubt hands the
    # request to the full application, whose FrameReader reads through read_verified
    "api/fast_frames.py": "checked by the frame summary; defers to FrameReader on any doubt",
}


def _modules() -> list[Path]:
    return [p for room in ROOMS for p in (ROOT / room).rglob("*.py") if "__pycache__" not in p.parts]


def test_every_reader_of_a_copy_reads_through_read_verified():
    offenders = []
    for path in _modules():
        text = path.read_text()
        rel = str(path.relative_to(ROOT))
        if READS_A_COPY.search(text) and not CHECKED.search(text) and rel not in EXCEPTIONS:
            offenders.append(rel)
    assert not offenders, f"these read frames from copies without archive.reading.copies.read_verified: {offenders}"


def test_the_exceptions_still_exist_and_still_defer():
    for rel in EXCEPTIONS:
        text = (ROOT / rel).read_text()
        assert READS_A_COPY.search(text), f"{rel} no longer reads copies: remove it from EXCEPTIONS"
    assert "FrameReader" in (ROOT / "api/app.py").read_text()
