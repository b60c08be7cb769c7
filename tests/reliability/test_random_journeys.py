"""Random journeys with faults (issue 36): sequences of what users and faults do to a data root,
drawn by hypothesis's stateful testing, with one invariant checked after every step.

Steps: record (in-process, and a real ``thermcap record`` killed with SIGKILL once a segment has
closed), ring recording within a budget with and without a mark, recover (a session or one
file), archive (a random set of formats, with or without ``--delete-source``), scrub (with and
without ``--repair``), verify, gc, sync to a folder depot with the depot's receipts and
``--delete-confirmed``, serve and read every frame over the API.
Faults: flip a byte in, truncate or remove an archive file or a segment; flip a bit of a closed
segment's summary; zero part of an HDF5 archive's global heap; put a segment the archive never
covered back beside an archived session (from the depot).

The model is what exists: for every frame ever seen, its pixels' sha256 (the truth), and after
each step the set of frames readable bit-exact from some copy (a segment in the session or in
the depot, or any archive format's files decoded by that format's reader). The invariant:

- a command (anything but a fault) never makes a readable frame unreadable: no command leaves
  the root worse than it found it, whatever it exits with;
- a recording that returned says how many frames it wrote, and exactly those are readable;
- ``serve`` lists and serves bit-exact every readable frame of every session it indexes, and
  serves no listed frame with other pixels; ``thermcap.open`` on each folder does the same.

The default run is the fixed, derandomized journey set (the same every run, so a failure in CI
reproduces) and one scripted journey that walks every rule (the fixed set drew neither serve
nor scrub); THERMCAP_JOURNEYS=N adds N fresh random sets (the long form, e.g. 50). The
figures (sequences and steps) are printed at the end.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import traceback
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule, run_state_machine_as_test

from thermcap.recorder.storage.reader import iter_segment_frames

pytestmark = pytest.mark.slow

W, H = 32, 24
FORMATS = ["png16", "tiff-lzw", "hdf5"]
STATS = {"sequences": 0, "steps": 0, "by_rule": {}}


def _sha(px: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(px, "<u2").tobytes()).hexdigest()


def _segment_frames(path: Path) -> dict[int, str]:
    """(time -> pixel sha256) of what one segment yields before it fails, if it does."""
    out: dict[int, str] = {}
    try:
        for f in iter_segment_frames(path):
            out[f.log_time] = _sha(f.pixels)
    except Exception:  # a damaged segment gives what it gives
        pass
    return out


def _archived_frames(session: Path) -> dict[str, dict[int, str]]:
    """Per archive format on disk: (time -> pixel sha256) its files decode to, file by file."""
    from thermcap.archive.formats import get_format

    mpath = session / "archive" / "manifest.json"
    try:
        m = json.loads(mpath.read_text())
    except (OSError, ValueError):
        return {}
    times = m.get("frames", {}).get("timestamps_ns") or []
    out: dict[str, dict[int, str]] = {}
    for fid, entry in m.get("formats", {}).items():
        fdir = session / "archive" / fid
        if not fdir.is_dir():
            continue
        got: dict[int, str] = {}
        index = 0
        for rec in entry.get("files", []):
            try:
                for k, frame in enumerate(get_format(entry.get("config") or fid).read(fdir, [rec["path"]])):
                    t = frame.log_time if frame.log_time is not None else times[index + k]
                    got[t] = _sha(frame.pixels)
            except Exception:
                pass
            index += rec["frames"]
        out[fid] = got
    return out


class Journeys(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        import tempfile

        self.tmp = Path(tempfile.mkdtemp(prefix="thermcap-journey-"))
        self.root = self.tmp / "root"
        self.depot = self.tmp / "depot"
        self.truth: dict[tuple[str, int], str] = {}  # (session, time) -> pixel sha256, as first recorded
        self.readable: set[tuple[str, int]] = set()
        self.local: set[tuple[str, int]] = set()  # readable from this root (what its API can serve)
        self.segment_of: dict[tuple[str, int], str] = {}  # the segment a frame was recorded in
        self.n = 0
        self.last = ""
        STATS["sequences"] += 1

    def teardown(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)

    # -- the model -----------------------------------------------------------------------------
    def sessions(self) -> list[Path]:
        base = self.root / "sessions"
        return sorted(p for p in base.iterdir() if p.is_dir()) if base.is_dir() else []

    def observe(self) -> tuple[set[tuple[str, int]], set[tuple[str, int]]]:
        """(every (session, time) readable bit-exact from some copy now, those readable from this
        root alone); learns the truth of frames it has not seen before from their first copy."""
        seen: set[tuple[str, int]] = set()
        local: set[tuple[str, int]] = set()
        for s in self.sessions():
            here = []
            for seg in sorted(s.glob("[0-9][0-9][0-9][0-9].mcap")):
                here.append(_segment_frames(seg))
                for t in here[-1]:
                    self.segment_of.setdefault((s.name, t), seg.name)
            # every intact file serves its frames, in a copy scrub marked damaged too: a damaged
            # part hides only itself
            here = here + list(_archived_frames(s).values())
            depot = self.depot / "sessions" / s.name
            there = [_segment_frames(seg) for seg in sorted(depot.glob("[0-9][0-9][0-9][0-9].mcap"))] \
                if depot.is_dir() else []
            for copies, into in ((here, local), (there, None)):
                for copy in copies:
                    for t, sha in copy.items():
                        key = (s.name, t)
                        if sha == self.truth.setdefault(key, sha):
                            seen.add(key)
                            if into is not None:
                                into.add(key)
        return seen, local

    def step(self, name: str) -> None:
        STATS["steps"] += 1
        STATS["by_rule"][name] = STATS["by_rule"].get(name, 0) + 1
        self.last = name

    def command_done(self, name: str) -> None:
        """After a command (not a fault): nothing readable before it is unreadable now."""
        now, self.local = self.observe()
        lost = self.readable - now - self.reported_lost()
        assert not lost, f"{name} made {len(lost)} frames unreadable, e.g. {sorted(lost)[:3]}"
        self.readable = now

    def reported_lost(self) -> set[tuple[str, int]]:
        """Frames a command reported gone by name: the ring's evictions, segment by segment, in
        ROOT/eviction.log (the ring deletes by design, and says what)."""
        log = self.root / "eviction.log"
        if not log.is_file():
            return set()
        gone = {(e["session"], e["segment"]) for e in map(json.loads, log.read_text().splitlines()) if "segment" in e}
        return {k for k, seg in self.segment_of.items() if (k[0], seg) in gone}

    def fault_done(self) -> None:
        self.readable, self.local = self.observe()

    # -- what users do ---------------------------------------------------------------------------
    @rule(frames=st.integers(10, 50), seg_s=st.sampled_from([0.1, 0.25, 1.0]))
    def record(self, frames: int, seg_s: float) -> None:
        from thermcap.recorder.capture.recorder import Recorder
        from thermcap.recorder.capture.sources.sim import SimSource
        from thermcap.recorder.storage.segments import SegmentPolicy

        self.step("record")
        self.n += 1
        sid = f"s{self.n}"
        res = Recorder(SimSource(width=W, height=H, frames=frames, paced=False, seed=self.n,
                                 start_time_ns=1_800_000_000_000_000_000 + self.n * 10**12),
                       self.root, session_id=sid, analysis=False, recover_leftovers=False,
                       policy=SegmentPolicy(max_duration_s=seg_s, chunk_size=8 << 10)).run()
        assert res.error is None, res.error
        self.command_done("record")
        written = {k for k in self.readable if k[0] == sid}
        assert len(written) == res.frames_written == frames, (len(written), res.frames_written)

    @precondition(lambda self: self.n < 8)
    @rule(frames=st.integers(60, 200), mark=st.booleans(), window_s=st.sampled_from([0.5, 1e8]))
    def ring_record(self, frames: int, mark: bool, window_s: float) -> None:
        """Always-on recording in a budget a little above what the root holds: it must evict
        (its own older segments, or an earlier ring session's), log every eviction, keep
        recording through a protected window (past its share the window expires, logged), and
        write every frame it was given."""
        from thermcap.recorder.capture.recorder import Recorder
        from thermcap.recorder.capture.sources.sim import SimSource
        from thermcap.recorder.storage.ring import RingPolicy, disk_usage, read_eviction_log
        from thermcap.recorder.storage.segments import SegmentPolicy

        self.step("ring_record")
        self.n += 1
        sid = f"s{self.n}"
        budget = (disk_usage(self.root) if self.root.is_dir() else 0) + 80_000
        ring = RingPolicy(max_disk=budget, pre_s=window_s, post_s=window_s, interval_s=0.02)
        rec = Recorder(SimSource(width=W, height=H, frames=frames, paced=False, seed=self.n, cue_period_s=0,
                                 start_time_ns=1_800_000_000_000_000_000 + self.n * 10**12),
                       self.root, session_id=sid, analysis=False, recover_leftovers=False,
                       policy=SegmentPolicy(max_duration_s=0.1, chunk_size=8 << 10), ring=ring)
        if mark:
            rec.mark("journey")
        res = rec.run()
        assert res.error is None, res.error
        assert res.frames_written == res.frames_captured == frames and res.frames_dropped == 0, res
        self.command_done("ring_record")
        kept = sum(1 for k in self.readable if k[0] == sid)
        evicted = sum(e.get("frames", 0) for e in read_eviction_log(self.root)
                      if e.get("session") == sid and "segment" in e)  # not the expired-window entries
        assert kept + evicted == frames, (kept, evicted, frames)

    @precondition(lambda self: self.n < 6)
    @rule()
    def record_killed(self) -> None:
        """A real recorder, killed with SIGKILL once its first segment has closed."""
        from tests.conftest import wait_for

        self.step("record_killed")
        self.n += 1
        sid = f"s{self.n}"
        proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(self.root), "--session",
                                 sid, "--width", str(W), "--height", str(H), "--duration", "30", "--no-analysis",
                                 "--segment-duration", "0.2", "--seed", str(self.n)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        session = self.root / "sessions" / sid
        try:
            assert wait_for(lambda: len(list(session.glob("[0-9][0-9][0-9][0-9].mcap"))) >= 1 + self.n % 2, 60)
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait(30)
        self.command_done("record_killed")

    @precondition(lambda self: self.sessions())
    @rule(data=st.data(), whole=st.booleans())
    def recover(self, data: st.DataObject, whole: bool) -> None:
        from thermcap.recorder.exceptions import McapFileError
        from thermcap.recorder.storage.recover import recover_path

        self.step("recover")
        s = data.draw(st.sampled_from(self.sessions()))
        files = sorted(s.glob("*.mcap*"))
        target = s if whole or not files else data.draw(st.sampled_from(files))
        if target.is_file() and not (target.name.endswith(".mcap") or target.name.endswith(".active")):
            target = s
        with contextlib.suppress(McapFileError):  # refused, with a reason: allowed if nothing was lost
            recover_path(target)
        self.command_done("recover")

    @precondition(lambda self: self.sessions())
    @rule(data=st.data(), formats=st.sets(st.sampled_from(FORMATS), min_size=1, max_size=3),
          delete=st.booleans())
    def archive(self, data: st.DataObject, formats: set[str], delete: bool) -> None:
        from thermcap.archive.archiver import archive_session
        from thermcap.recorder.exceptions import ThermcapError

        self.step("archive")
        s = data.draw(st.sampled_from(self.sessions()))
        with contextlib.suppress(ThermcapError):
            archive_session(s, sorted(formats), delete_source=delete)
        self.command_done("archive")

    @precondition(lambda self: self.sessions())
    @rule(data=st.data())
    def archive_then_delete_source(self, data: st.DataObject) -> None:
        """The journey the archiver exists for, drawn as often as the rest: every default format, then
        the source goes (the command re-checks every copy first)."""
        self.archive(data, set(FORMATS), True)

    @precondition(lambda self: any((s / "archive" / "manifest.json").is_file() for s in self.sessions()))
    @rule(repair=st.booleans())
    def scrub(self, repair: bool) -> None:
        from thermcap.archive.scrub import scrub_root

        self.step("scrub")
        scrub_root(self.root, repair=repair)
        self.command_done("scrub")

    @precondition(lambda self: any((s / "archive" / "manifest.json").is_file() for s in self.sessions()))
    @rule()
    def verify(self) -> None:
        from thermcap.archive.verify import verify_session

        self.step("verify")
        for s in self.sessions():
            if (s / "archive" / "manifest.json").is_file():
                verify_session(s)
        self.command_done("verify")

    @precondition(lambda self: self.sessions())
    @rule()
    def gc(self) -> None:
        from thermcap.api.jobs.retention import gc_sessions

        self.step("gc")
        gc_sessions(self.root, keep_days=0, max_bytes=None, require_upload=False, dry_run=False)
        self.command_done("gc")

    @precondition(lambda self: self.sessions())
    @rule(delete=st.booleans())
    def sync(self, delete: bool) -> None:
        from thermcap.archive.blobs import open_store
        from thermcap.archive.receipts import confirm_synced
        from thermcap.recorder.sync.engine import Syncer
        from thermcap.recorder.sync.targets import DirTarget

        self.step("sync")
        syncer = Syncer(self.root, DirTarget(self.depot), part_size=5 << 20)
        syncer.run_once()
        confirm_synced(open_store(self.depot))
        syncer.check_receipts()
        if delete:
            syncer.delete_confirmed()
        self.command_done("sync")

    @precondition(lambda self: self.sessions())
    @rule()
    def serve(self) -> None:
        """Every readable frame of every session the API indexes is listed and served bit-exact."""
        from fastapi.testclient import TestClient

        from thermcap.api.app import create_app
        from thermcap.api.settings import Settings

        self.step("serve")
        with TestClient(create_app(Settings(root=self.root, tokens={}, rescan_interval_s=0))) as c:
            listed = {s["id"] for s in c.get("/api/v1/sessions", params={"limit": 1000}).json()["items"]}
            for s in self.sessions():
                want = {t for (sid, t) in self.local if sid == s.name}
                if s.name not in listed:
                    assert not want, f"serve: session {s.name} has {len(want)} readable frames and is not listed"
                    continue
                items = c.get(f"/api/v1/sessions/{s.name}/frames", params={"limit": 1000}).json()["items"]
                times = {it["timestamp_ns"]: it["index"] for it in items}
                missing = want - set(times)
                assert not missing, f"serve: {len(missing)} readable frames of {s.name} are not listed"
                for t in sorted(want):
                    r = c.get(f"/api/v1/sessions/{s.name}/frames/{times[t]}", params={"format": "raw"})
                    assert r.status_code == 200, (s.name, t, r.status_code, r.text[:200])
                    assert hashlib.sha256(r.content).hexdigest() == self.truth[(s.name, t)], (s.name, t)
                # a listed frame no copy holds readable is refused, never served as other pixels
                for t in sorted(set(times) - want):
                    if (s.name, t) not in self.truth:
                        continue
                    r = c.get(f"/api/v1/sessions/{s.name}/frames/{times[t]}", params={"format": "raw"})
                    assert r.status_code != 200 or hashlib.sha256(r.content).hexdigest() == self.truth[(s.name, t)], \
                        f"serve: frame at {t} of {s.name} served with another frame's pixels"
        self._open_reads_the_same()
        self.command_done("serve")

    def _open_reads_the_same(self) -> None:
        """``thermcap.open(folder)`` numbers and reads as the server does: every readable frame
        bit-exact at its time, and no frame it gives carries another's pixels."""
        import thermcap

        for s in self.sessions():
            want = {t for (sid, t) in self.local if sid == s.name}
            try:
                session = thermcap.open(s)
            except Exception:
                assert not want, f"open: {s.name} has {len(want)} readable frames and does not open"
                continue
            at = {int(t): i for i, t in enumerate(session.table.timestamp_ns)}
            assert want <= set(at), f"open: {len(want - set(at))} readable frames of {s.name} are not numbered"
            for t, i in at.items():
                try:
                    px = session.counts(i)
                except LookupError:
                    assert t not in want, f"open: readable frame at {t} of {s.name} refused"
                    continue
                if (s.name, t) in self.truth:
                    assert _sha(px) == self.truth[(s.name, t)], f"open: frame at {t} of {s.name} has other pixels"

    # -- faults ----------------------------------------------------------------------------------
    def _files(self, archive: bool) -> list[Path]:
        out = []
        for s in self.sessions():
            if archive:
                for fid in FORMATS:
                    out += sorted(p for p in (s / "archive" / fid).glob("*") if p.is_file())
            else:
                out += sorted(s.glob("[0-9][0-9][0-9][0-9].mcap"))
        return out

    def _damage(self, data: st.DataObject, files: list[Path], kind: str) -> None:
        self.step(f"damage:{kind}")
        path = data.draw(st.sampled_from(files))
        raw = bytearray(path.read_bytes())
        if kind == "remove":
            path.unlink()
        elif kind == "truncate":
            path.write_bytes(bytes(raw[: len(raw) * data.draw(st.integers(1, 9)) // 10]))
        elif raw:
            at = data.draw(st.integers(0, len(raw) - 1))
            raw[at] ^= 1 << data.draw(st.integers(0, 7))
            path.write_bytes(bytes(raw))
        self.fault_done()

    @precondition(lambda self: self._files(True))
    @rule(data=st.data(), kind=st.sampled_from(["flip", "flip", "truncate", "remove"]))
    def damage_archive(self, data: st.DataObject, kind: str) -> None:
        self._damage(data, self._files(True), kind)

    @precondition(lambda self: self._files(False))
    @rule(data=st.data(), kind=st.sampled_from(["flip", "truncate", "remove"]))
    def damage_segment(self, data: st.DataObject, kind: str) -> None:
        self._damage(data, self._files(False), kind)

    @precondition(lambda self: self._files(False))
    @rule(data=st.data())
    def damage_summary(self, data: st.DataObject) -> None:
        """One bit of a closed segment's summary section (the chunk indexes, the statistics): the
        frames are intact, the map to them is not (issue 65, defect 1)."""
        self.step("damage:summary")
        path = data.draw(st.sampled_from(self._files(False)))
        raw = bytearray(path.read_bytes())
        footer = len(raw) - 8 - 29  # the footer record (opcode, length, two offsets, CRC) before the magic
        if footer > 0 and raw[footer] == 0x02:
            start = int.from_bytes(raw[footer + 9:footer + 17], "little")
            if 8 <= start < footer:
                at = data.draw(st.integers(start, footer - 1))
                raw[at] ^= 1 << data.draw(st.integers(0, 7))
                path.write_bytes(bytes(raw))
        self.fault_done()

    @precondition(lambda self: any(self._h5s()))
    @rule(data=st.data())
    def damage_hdf5_heap(self, data: st.DataObject) -> None:
        """4 KiB of an HDF5 archive's global heap (the sidecar strings) zeroed: a reader must
        fail cleanly, never hang (defect 5)."""
        self.step("damage:hdf5-heap")
        path = data.draw(st.sampled_from(self._h5s()))
        raw = bytearray(path.read_bytes())
        at = raw.find(b"GCOL")
        if at >= 0:
            raw[at + 16:at + 16 + 4096] = bytes(len(raw[at + 16:at + 16 + 4096]))
            path.write_bytes(bytes(raw))
        self.fault_done()

    def _h5s(self) -> list[Path]:
        return [p for s in self.sessions() for p in sorted((s / "archive" / "hdf5").glob("*.h5"))]

    @precondition(lambda self: self._unseen_candidates())
    @rule(data=st.data())
    def put_back_an_unseen_segment(self, data: st.DataObject) -> None:
        """A segment the archive never covered appears beside an archived session (restored from
        a depot, renamed back from ``.unreadable``): archive and gc must not delete it on the
        archive's evidence (defect 6). Here: a segment from the depot, put in under the next free
        number."""
        self.step("fault:unseen-segment")
        session, segment = data.draw(st.sampled_from(self._unseen_candidates()))
        folder = self.root / "sessions" / session
        taken = {p.name for p in folder.glob("[0-9][0-9][0-9][0-9].mcap*")} | {
            str(x) for x in (json.loads((folder / "archive" / "manifest.json").read_text()).get("frames") or {}
                             ).get("segments") or []}
        name = next(f"{k:04d}.mcap" for k in range(10_000) if f"{k:04d}.mcap" not in taken)
        shutil.copy2(segment, folder / name)
        self.fault_done()

    def _unseen_candidates(self) -> list[tuple[str, Path]]:
        depot = sorted((self.depot / "sessions").glob("*/[0-9][0-9][0-9][0-9].mcap")) \
            if (self.depot / "sessions").is_dir() else []
        return [(s.name, seg) for s in self.sessions() if (s / "archive" / "manifest.json").is_file()
                for seg in depot]

    @invariant()
    def nothing_readable_is_unaccounted(self) -> None:
        # the model's own consistency: what it holds readable was readable when last observed
        assert self.readable <= set(self.truth)


#: Fresh random journey sets beyond the fixed (derandomized) ones. The default run keeps to the
#: fixed sets, so a CI failure is always reproducible; THERMCAP_JOURNEYS=N adds N random sets.
RANDOM = int(os.environ.get("THERMCAP_JOURNEYS", "0"))

#: the first exception a step raised in the current set, with its traceback: a journey touches
#: real processes and clocks, so hypothesis's replay of a failing sequence may draw differently
#: and report only FlakyStrategyDefinition, hiding what failed (5 of 6 failures in a 250-set run)
FIRST_FAILURE: list[str] = []


def _recorded(step: Any) -> Any:
    @functools.wraps(step)
    def run(*args: Any, **kwargs: Any) -> Any:
        try:
            return step(*args, **kwargs)
        except BaseException:
            if not FIRST_FAILURE:
                FIRST_FAILURE.append(f"{step.__name__}{kwargs or ''}:\n{traceback.format_exc()}")
            raise

    return run


# hypothesis calls the function its rule and invariant marks hold: those are what is wrapped
for _step in list(vars(Journeys).values()):
    if (_rule := getattr(_step, "hypothesis_stateful_rule", None)) is not None:
        _rule.function = _recorded(_rule.function)
    if (_inv := getattr(_step, "hypothesis_stateful_invariant", None)) is not None:
        _step.hypothesis_stateful_invariant = dataclasses.replace(_inv, function=_recorded(_inv.function))


@pytest.mark.parametrize("which", ["fixed", *[f"random-{k}" for k in range(RANDOM)]])
def test_random_journeys(which: str, capsys) -> None:
    """The fixed journey set (derandomized: the same every run) and RANDOM fresh ones; a failure
    prints the shrunk sequence and hypothesis's @reproduce_failure line."""
    before, seqs = STATS["steps"], STATS["sequences"]
    FIRST_FAILURE.clear()
    try:
        run_state_machine_as_test(Journeys, settings=settings(
            max_examples=4, stateful_step_count=20, deadline=None, database=None, derandomize=which == "fixed",
            # shrinking a journey re-runs real recordings for many minutes: off unless asked for
            phases=list(Phase) if os.environ.get("THERMCAP_JOURNEYS_SHRINK") else [Phase.explicit, Phase.generate],
            suppress_health_check=list(HealthCheck)))
    except Exception as exc:
        if FIRST_FAILURE:
            raise AssertionError(f"the first step that failed in {which}: {FIRST_FAILURE[0]}") from exc
        raise
    with capsys.disabled():
        print(f"\njourneys {which}: {STATS['sequences'] - seqs} sequences, {STATS['steps'] - before} steps; "
              f"all so far: {STATS['sequences']} sequences, {STATS['steps']} steps, by rule {STATS['by_rule']}")


class _Scripted:
    """``st.data()`` for a scripted journey: a sampled element by the index given (the first by
    default), an integer at the middle of its range."""

    def __init__(self, *picks: int) -> None:
        self.picks = list(picks)

    def draw(self, strategy: st.SearchStrategy) -> object:
        inner = getattr(strategy, "wrapped_strategy", strategy)
        if hasattr(inner, "elements"):
            elements = list(inner.elements)
            return elements[(self.picks.pop(0) if self.picks else 0) % len(elements)]
        return (inner.start + inner.end) // 2


#: The journey a field team walks when a copy rots: every rule the random sets may draw rarely
#: (serve, scrub, repair, the ring, a killed recorder) runs here in every CI run, in this order.
SCRIPT = [
    ("record", {"frames": 30, "seg_s": 0.25}),
    ("archive", {"data": _Scripted(), "formats": {"png16"}, "delete": True}),
    ("damage_archive", {"data": _Scripted(), "kind": "flip"}),
    ("scrub", {"repair": False}),
    ("serve", {}),
    ("record_killed", {}),
    ("recover", {"data": _Scripted(1), "whole": True}),
    ("sync", {"delete": True}),
    ("archive_then_delete_source", {"data": _Scripted(1)}),
    ("put_back_an_unseen_segment", {"data": _Scripted()}),  # sync freed it before the archive ran
    ("serve", {}),
    ("damage_archive", {"data": _Scripted(-1), "kind": "truncate"}),
    ("scrub", {"repair": True}),
    ("verify", {}),
    ("ring_record", {"frames": 80, "mark": True, "window_s": 0.5}),
    ("damage_summary", {"data": _Scripted(-1)}),
    ("serve", {}),
    ("archive", {"data": _Scripted(-1), "formats": {"hdf5", "tiff-lzw"}, "delete": False}),
    ("damage_hdf5_heap", {"data": _Scripted()}),
    ("damage_segment", {"data": _Scripted(), "kind": "remove"}),
    ("gc", {}),
    ("serve", {}),
]


def test_the_scripted_journey(capsys) -> None:
    """Every rule at least once, with the invariant after each step, whatever the random sets drew."""
    machine = Journeys()
    try:
        for name, kwargs in SCRIPT:
            getattr(machine, name)(**kwargs)
            machine.nothing_readable_is_unaccounted()
    finally:
        machine.teardown()
    ran = {name for name, _ in SCRIPT}
    rules = {n for n in dir(Journeys) if hasattr(getattr(Journeys, n), "hypothesis_stateful_rule")}
    assert rules <= ran, f"rules the script does not walk: {sorted(rules - ran)}"
    with capsys.disabled():
        print(f"\njourneys scripted: 1 sequence, {len(SCRIPT)} steps")
