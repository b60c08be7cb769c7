"""The detector in a child process: the same answers as in the recording process, in order,
with bounded slots; a live source is never made to wait; a child that dies or cannot start
never hangs a recording nor silently loses an answer.

Real child processes throughout. Where a test needs the child busy, it stops it with SIGSTOP
rather than hoping a frame takes long enough."""

from __future__ import annotations

import os
import signal
from concurrent.futures import Future
from pathlib import Path

import numpy as np
import pytest

from thermcap.recorder.analysis.answers import Unanalysable
from thermcap.recorder.analysis.detector import HotSpotDetector
from thermcap.recorder.analysis.process_runner import ProcessRunner
from thermcap.recorder.analysis.runner import ThreadRunner, start_runner
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.raw import RawSource
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.radiometry import DEFAULT_MODEL
from thermcap.recorder.storage.reader import iter_session_frames


def _frames(n: int = 12, w: int = 320, h: int = 256) -> list[np.ndarray]:
    return [f.pixels.copy() for f in SimSource(width=w, height=h, frames=n, seed=3).frames()]


def _submitted(runner, frames: list[np.ndarray]) -> list[Future]:
    futs = []
    for px in frames:
        fut: Future = Future()
        assert runner.submit(px, fut, wait=True)
        futs.append(fut)
    return futs


def _answers(runner, frames: list[np.ndarray]) -> list:
    return [f.result(timeout=60) for f in _submitted(runner, frames)]


def _plain(answer):
    if answer is None or isinstance(answer, Unanalysable):
        return answer
    dets, analysis = answer
    return [d.to_sidecar() for d in dets], analysis


def _in_process(frames: list[np.ndarray]) -> list:
    det = HotSpotDetector(SimSource(frames=1).model)
    return [_plain(det.detect(px)) for px in frames]


def _through_a_child(frames: list[np.ndarray], slots: int) -> tuple[ProcessRunner, list]:
    """The same frames' answers from a detector in a child process, which is closed after."""
    runner = ProcessRunner(HotSpotDetector(SimSource(frames=1).model), slots=slots, frame_bytes=frames[0].nbytes)
    try:
        return runner, [_plain(a) for a in _answers(runner, frames)]
    finally:
        runner.close(30)


def test_the_child_answers_as_the_detector_does_in_process_with_ids_kept_across_frames():
    frames = _frames()
    expected = _in_process(frames)
    assert any(e[0] for e in expected), "the scene must hold targets for the comparison to mean anything"
    runner, got = _through_a_child(frames, slots=3)
    assert got == expected
    assert runner.cpu_s > 0
    assert runner._proc.poll() is not None  # the child is gone


def test_a_child_that_is_behind_answers_in_batches_and_an_idle_one_at_once():
    """Issue 40: the recorder's results thread woke once a frame, a wake-up and a message each;
    a child with frames waiting sends up to a quarter of its slots' results in one message."""
    frames = _frames(10)
    model = SimSource(frames=1).model
    det = HotSpotDetector(model)
    expected = [_plain(det.detect(px)) for px in frames]
    runner = ProcessRunner(HotSpotDetector(model), slots=8, frame_bytes=frames[0].nbytes)  # batches of 2
    try:
        os.kill(runner.pid, signal.SIGSTOP)  # all eight frames wait in its socket when it resumes
        futs = _submitted(runner, frames[:8])
        os.kill(runner.pid, signal.SIGCONT)
        got = [_plain(f.result(timeout=60)) for f in futs]
        assert runner.answer_messages == 4
        got += [_plain(a) for a in _answers(runner, frames[8:9])]  # idle: answered at once, alone
        assert runner.answer_messages == 5
        got += [_plain(a) for a in _answers(runner, frames[9:])]
        assert runner.answer_messages == 6
    finally:
        runner.close(30)
    assert got == expected


def test_a_frame_larger_than_a_slot_still_reaches_the_detector():
    frames = _frames(2, 640, 512)
    model = SimSource(frames=1).model
    runner = ProcessRunner(HotSpotDetector(model), slots=2, frame_bytes=320 * 256 * 2)
    try:
        got = [_plain(a) for a in _answers(runner, frames)]
    finally:
        runner.close(30)
    det = HotSpotDetector(model)
    assert got == [_plain(det.detect(px)) for px in frames]


def _blob_and_flat_frames() -> list[np.ndarray]:
    """A warm target, a flat view, the target again at the same place, then flat views between
    targets: the detector gives the third frame a new id (the flat frame ended the track)."""
    rng = np.random.default_rng(1)

    def blob(y: int, x: int) -> np.ndarray:
        f = np.rint(2000 + rng.normal(0, 0.4, (96, 128))).astype(np.uint16)
        f[y:y + 8, x:x + 8] += 400  # 14 K above a 20 C wall at 0.036 K a count
        return f

    flat = np.full((96, 128), 2000, np.uint16)
    return [blob(20, 30), flat, blob(20, 30), blob(21, 31), flat, flat, blob(21, 31), blob(60, 90)]


def test_a_flat_frame_is_answered_without_the_child_which_still_ends_the_tracks_it_would_have():
    """Issue 40: handing a flat frame (a wall, a lens cap) to the child cost a file source more
    than the detector's answer. Answered in the recorder, exactly; the next frame sent tells the
    child to forget its tracks, so every id is the in-process detector's."""
    frames = _blob_and_flat_frames()
    expected = _in_process(frames)
    ids = [[t["target_id"] for t in e[0]] for e in expected]
    assert ids[0] == ["HS00001"] and ids[2] == ["HS00002"], "the flat frame must end the first track"
    runner, got = _through_a_child(frames, slots=2)
    assert got == expected
    assert runner.answered_here == 3


def test_a_live_source_never_waits_for_a_busy_child():
    frames = _frames(3)
    runner = ProcessRunner(HotSpotDetector(SimSource(frames=1).model), slots=1, frame_bytes=frames[0].nbytes)
    os.kill(runner.pid, signal.SIGSTOP)  # the child holds the only slot and cannot answer
    try:
        first: Future = Future()
        assert runner.submit(frames[0], first, wait=False)
        second: Future = Future()
        assert not runner.submit(frames[1], second, wait=False)  # no slot: skipped, not waited for
        assert not first.done()
    finally:
        os.kill(runner.pid, signal.SIGCONT)
    assert first.result(timeout=60) is not None
    third: Future = Future()
    assert runner.submit(frames[2], third, wait=True)  # the slot is free again
    assert third.result(timeout=60) is not None
    runner.close(30)


def test_a_child_that_dies_answers_none_for_what_it_held_and_everything_after():
    frames = _frames(4)
    runner = ProcessRunner(HotSpotDetector(SimSource(frames=1).model), slots=2, frame_bytes=frames[0].nbytes)
    os.kill(runner.pid, signal.SIGSTOP)
    held = _submitted(runner, frames[:2])
    os.kill(runner.pid, signal.SIGKILL)
    assert [f.result(timeout=60) for f in held] == [None, None]
    assert runner.failure is not None and "exit code -9" in runner.failure
    late: Future = Future()
    assert not runner.submit(frames[2], late, wait=True)  # never blocks on a dead child
    runner.close(5)


def test_a_detector_that_cannot_reach_a_child_runs_in_a_thread_and_says_why():
    det = HotSpotDetector(SimSource(frames=1).model)
    det.model = type("Unpicklable", (), {"to_celsius": lambda self, raw: raw})()  # a local class
    runner, why = start_runner(det, 2, 1024, name="t")
    try:
        assert isinstance(runner, ThreadRunner)
        assert why is not None and "cannot be sent to a child process" in why
    finally:
        runner.close(5)


def _raw_file(tmp_path: Path, frames: list[np.ndarray]) -> Path:
    path = tmp_path / "scene.raw"
    np.stack(frames).astype("<u2").tofile(path)
    return path


@pytest.mark.parametrize("runner", ["process", "thread"])
def test_every_frame_of_a_file_is_analysed_and_both_runners_record_the_same_sidecars(tmp_path, runner):
    frames = _frames(40)
    path = _raw_file(tmp_path, frames)
    rec = Recorder(RawSource(str(path), width=320, height=256, model=DEFAULT_MODEL), tmp_path / runner,
                   recover_leftovers=False, analysis_runner=runner, analysis_queue=2)
    res = rec.run()
    assert res.error is None and res.frames_written == 40 and res.analysis_skipped == 0
    assert res.analysis_runner is not None and res.analysis_runner["runner"] == runner
    assert res.analysis_runner["failure"] is None
    analyses = [f.sidecar_dict()["thermal_analysis"] for f in iter_session_frames(res.session_dir)]
    targets = [f.sidecar_dict()["targets"] for f in iter_session_frames(res.session_dir)]
    assert all(a["source"] == "detector" for a in analyses)
    det = HotSpotDetector(DEFAULT_MODEL)
    expected = [_plain(det.detect(px)) for px in frames]
    assert targets == [e[0] for e in expected]
    assert any(targets)


@pytest.mark.parametrize("runner", ["process", "thread"])
def test_a_file_with_flat_views_between_targets_records_the_same_sidecars_either_way(tmp_path, runner):
    frames = _blob_and_flat_frames() * 3
    path = _raw_file(tmp_path, frames)
    rec = Recorder(RawSource(str(path), width=128, height=96, model=DEFAULT_MODEL), tmp_path / runner,
                   recover_leftovers=False, analysis_runner=runner, analysis_queue=2)
    res = rec.run()
    assert res.error is None and res.frames_written == len(frames) and res.analysis_skipped == 0
    assert res.analysis_runner["answered_in_recorder"] == (9 if runner == "process" else 0)
    sidecars = [f.sidecar_dict() for f in iter_session_frames(res.session_dir)]
    det = HotSpotDetector(DEFAULT_MODEL)
    expected = [_plain(det.detect(px)) for px in frames]
    assert [s["targets"] for s in sidecars] == [e[0] for e in expected]
    assert [s["thermal_analysis"] for s in sidecars] == [{**e[1]} for e in expected]


def test_the_recording_says_where_the_detector_ran_and_no_child_outlives_it(tmp_path):
    rec = Recorder(SimSource(width=160, height=128, frames=30, paced=False, seed=1), tmp_path, recover_leftovers=False)
    res = rec.run()
    assert res.analysis_runner["runner"] == "process"
    assert res.to_dict()["analysis_runner"]["fallback"] is None
    proc = rec.feeds[0].runner._proc  # type: ignore[union-attr]
    assert proc.poll() is not None


@pytest.mark.parametrize(("paced", "frame_bytes", "queue", "slots"), [
    (False, 160 * 128 * 2, 8, 32),    # a source that waits: a deep ring
    (False, 160 * 128 * 2, 40, 40),   # never fewer than asked for
    (True, 160 * 128 * 2, 8, 8),      # a live camera: what analysis_queue says
    (False, 4096 * 4096 * 2, 2, 2),   # 32 MB frames: the ring's bytes bound it, never below what was asked
])
def test_a_source_that_waits_gets_a_deep_ring_of_slots_within_its_bytes(tmp_path, paced, frame_bytes, queue, slots):
    from thermcap.recorder.capture.recorder import FILE_ANALYSIS_SLOT_BYTES

    src = SimSource(width=160, height=128, frames=2, paced=paced, seed=1, fps=60.0)
    rec = Recorder(src, tmp_path, recover_leftovers=False, analysis_queue=queue)
    assert rec._analysis_slots(rec.feeds[0], frame_bytes) == slots
    if frame_bytes * slots > FILE_ANALYSIS_SLOT_BYTES:
        assert slots == queue
    if frame_bytes == 160 * 128 * 2:  # the recording says how many it had
        res = rec.run()
        assert res.error is None and res.analysis_runner["slots"] == [slots]


@pytest.mark.parametrize("users", [None, "3"])
def test_the_child_runs_one_blas_thread_unless_the_user_said_otherwise(monkeypatch, users):
    """The detector makes no BLAS call; numpy's and scipy's OpenBLAS pools had spun at import
    in the child, 0.1-0.3 s of CPU before the first frame. A user's own setting is kept."""
    if users is None:
        monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", users)
    runner = ProcessRunner(HotSpotDetector(DEFAULT_MODEL), 2, 64 * 64 * 2)
    try:
        environ = Path(f"/proc/{runner.pid}/environ").read_bytes().split(b"\0")
        assert f"OPENBLAS_NUM_THREADS={users or 1}".encode() in environ
    finally:
        runner.close(10.0)


def test_a_file_of_noise_says_which_cap_bit_and_how_long_the_recording_waited(tmp_path):
    """What tells a user why analysis slowed a file's recording: every frame of noise (sigma 45 counts) holds
    more candidate regions than a 320x256 frame examines (8), so each names max_regions; the
    result, its JSON and the command's summary say how often, and how long the writer waited."""
    from click.testing import CliRunner

    from thermcap.recorder.cli.root import cli

    rng = np.random.default_rng(7)
    frames = [(2000 + rng.normal(0, 45, (256, 320))).astype(np.uint16) for _ in range(12)]
    path = _raw_file(tmp_path, frames)
    res = Recorder(RawSource(str(path), width=320, height=256, model=DEFAULT_MODEL), tmp_path / "a",
                   recover_leftovers=False).run()
    capped = [f.sidecar_dict()["thermal_analysis"].get("detection_capped", {}).get("rule")
              for f in iter_session_frames(res.session_dir)]
    assert capped == ["max_regions"] * 12
    runner = res.to_dict()["analysis_runner"]
    assert runner["capped"] == {"max_regions": 12}
    assert 0.0 <= runner["waited_for_detector_s"] <= res.wall_s
    out = CliRunner().invoke(cli, ["record", "--root", str(tmp_path / "b"), "--source", f"raw:{path}",
                                   "--width", "320", "--height", "256"])
    assert out.exit_code == 0, out.output
    assert "analysis: a cap bit on 12 frames (max_regions 12): the view held more candidates" in out.output


class _AnsweredLate(Future):
    """A detector's answer that is not there yet when the writer asks (``done()`` starts the
    thread that gives it), so the writer must wait for it."""

    def __init__(self, answer) -> None:
        super().__init__()
        self._answer = answer
        self._started = False

    def done(self) -> bool:
        if not self._started:
            self._started = True
            import threading

            threading.Thread(target=self.set_result, args=(self._answer,)).start()
            return False
        return super().done()


def test_the_writers_wait_for_the_detector_is_counted_only_where_the_source_waits(tmp_path):
    from thermcap.recorder.capture.sources.base import CapturedFrame

    src = SimSource(width=64, height=48, frames=1, paced=False, seed=1)
    rec = Recorder(src, tmp_path, recover_leftovers=False)
    feed = rec.feeds[0]
    px = next(iter(src.frames())).pixels
    answer = HotSpotDetector(DEFAULT_MODEL).detect(px)
    rec.analysis_wait_s = 120.0  # a live source's wait for an answer: long enough never to matter here
    for can_wait in (True, False):
        feed.can_wait, feed.analysis_wait_ns = can_wait, 0
        frame = CapturedFrame(index=0, timestamp_ns=1, pixels=px)
        frame.analysis = _AnsweredLate(answer)
        if not can_wait:  # a live source never asks whether the answer is there: start it here
            frame.analysis.done()
        blocks = rec._sidecar_blocks(feed, frame)
        assert blocks["thermal_analysis"] == answer[1]
        assert (feed.analysis_wait_ns > 0) is can_wait


def test_the_summary_names_the_detectors_cost_only_where_a_waiting_source_felt_it():
    from thermcap.recorder.cli.record import analysis_notes

    costly = {"cpu_s": 1.0, "waited_for_detector_s": 0.4, "capped": {"max_regions": 900, "max_candidates": 3}}
    lines = analysis_notes(costly, wall_s=3.0, analysed=1000)
    assert lines[0].startswith("analysis: a cap bit on 903 frames (max_regions 900, max_candidates 3)")
    assert "the detector took 1.0 s of CPU (1.00 ms a frame) beside the recording, which waited 0.4 s of its " \
           "3.0 s" in lines[1]
    # a live camera never waits (nothing to say about its rate), nor does a cheap detector matter
    assert analysis_notes({"cpu_s": 1.0, "waited_for_detector_s": 0.0}, 3.0, 1000) == []
    assert analysis_notes({"cpu_s": 0.01, "waited_for_detector_s": 0.02}, 3.0, 1000) == []
    assert len(analysis_notes({"cpu_s": 0.01, "waited_for_detector_s": 0.5}, 3.0, 0)) == 1
