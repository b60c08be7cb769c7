"""Issue 36: ``ctl status`` called messages frames (2,307 "dropped" = 769 frames x 3 topics)."""

from thermcap.recorder.cli.record import status_text


def test_status_counts_dropped_frames_not_messages():
    st = {"session_id": "s", "paused": False, "healthy": True, "problems": [], "frames_captured": 1000,
          "frames_written": 231, "frames_paused": 0, "queue_depth": 0, "queue_capacity": 120, "segment": 1,
          "dropped": {"/thermal/image": 769, "/thermal/metadata": 769, "/thermal/annotations": 769},
          "cameras": {"SIM": {"frames_written": 231, "frames_dropped": 769, "error": None}}}
    text = status_text(st)
    assert "769 frames dropped" in text and "2307" not in text
