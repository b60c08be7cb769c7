"""One address book for the data root, checked from the code (issue 65's homes): the sessions
folder, the index's file, sync's folder and a session's object keys in a bucket are spelt in
``recorder/storage/layout.py`` only (``DataRoot``, ``session_key``, ``archive_key``). A module
that spells them itself fails here, naming the line, so a second spelling cannot drift from the
first (the recorder once wrote where the API no longer looked)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ROOMS = ("recorder", "archive", "api", "thermcap")
HOME = "recorder/storage/layout.py"

SPELLINGS = {
    "the sessions folder as a path": re.compile(r"""/\s*["']sessions["']"""),
    "a session's object key by hand": re.compile(r"""(?<![\w/])f?["']sessions/"""),
    "the index's file": re.compile(r"""["']index\.sqlite["']|/index\.sqlite"""),
    "sync's folder": re.compile(r"""["']\.sync["']"""),
    "the indexer's frame files": re.compile(r"""["']index/frames|/\s*["']index["']\s*/\s*["']frames["']"""),
}


def _code_lines(path: Path):
    """Lines of code, not of docstrings or comments (they may say where things are)."""
    in_doc = False
    for no, line in enumerate(path.read_text().splitlines(), 1):
        stripped = line.strip()
        quotes = stripped.count('"""') + stripped.count("'''")
        if in_doc:
            if quotes % 2:
                in_doc = False
            continue
        if stripped.startswith(('"""', "'''", 'r"""')) or stripped.endswith(('"""', "'''")):
            if quotes % 2:
                in_doc = True
            continue
        if stripped.startswith("#"):
            continue
        yield no, line.split("  #")[0]


def test_the_data_root_is_spelt_in_its_address_book_only():
    found = []
    for room in ROOMS:
        for path in sorted((ROOT / room).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel == HOME or "migrations" in path.parts:
                continue
            for no, line in _code_lines(path):
                for what, pattern in SPELLINGS.items():
                    if pattern.search(line):
                        found.append(f"{rel}:{no}: {what}: {line.strip()}")
    assert not found, "spelt outside recorder/storage/layout.py (use DataRoot / session_key / archive_key):\n" + \
        "\n".join(found)


def test_the_check_sees_a_spelling():
    """The patterns catch what they are for (a check that cannot fail proves nothing)."""
    lines = ['d = root / "sessions" / sid', 'key = f"sessions/{sid}/archive/x"', 'url = "sqlite:///r/index.sqlite"',
             'j = root / ".sync"', 'k = f"index/frames/{sid}/{s}.parquet"', 'root / "index" / "frames" / name']
    assert all(any(p.search(line) for p in SPELLINGS.values()) for line in lines)
    assert not any(p.search('"/api/v1/sessions/{sid}"') for p in SPELLINGS.values())
