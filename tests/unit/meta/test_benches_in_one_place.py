"""Benchmarks in one place (issue 65's house): every ``thermcap bench`` subcommand is defined in
``thermcap.benches``, above the three rooms, and no room holds a benchmark module; a second
timer or server-starter beside the harness is the duplicate the move ended."""

from __future__ import annotations

import re
from pathlib import Path

from thermcap.cli import cli

ROOT = Path(__file__).resolve().parents[3]


def test_every_bench_command_lives_in_thermcap_benches():
    bench = cli.commands["bench"]
    names = bench.list_commands(None)  # type: ignore[attr-defined]
    assert {"record", "archive", "api", "python", "cdr", "temporal", "index"} <= set(names)
    for name in names:
        command = bench.get_command(None, name)  # type: ignore[attr-defined]
        assert command.callback.__module__ == "thermcap.benches.cli", (name, command.callback.__module__)


def test_no_room_holds_a_benchmark():
    found = [p.relative_to(ROOT).as_posix() for room in ("recorder", "archive", "api")
             for p in (ROOT / room).rglob("*.py") if re.match(r"bench", p.name) or "bench" in p.parent.name]
    assert not found


def test_benches_time_and_serve_through_the_harness():
    own = {"harness.py", "cpu.py", "writer_run.py"}  # the harness; CPU per thread; a process timing itself
    found = []
    for p in sorted((ROOT / "thermcap" / "benches").glob("*.py")):
        if p.name in own:
            continue
        text = p.read_text()
        if re.search(r'"serve", "--root"|def _free_port\b|def _timed\b|def _pair\b', text):
            found.append(p.name)
    assert not found, f"start servers and time pairs through thermcap.benches.harness: {found}"
