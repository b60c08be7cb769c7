"""``thermcap --config FILE``: TOML defaults per command that flags override, cameras as
[[record.camera]], and every mistake named; the live branch never makes the writer wait."""

from __future__ import annotations

import json
import time

import numpy as np
from click.testing import CliRunner

from thermcap.cli import cli
from thermcap.recorder.live.branch import LiveBranch
from thermcap.recorder.live.publisher import LiveOptions
from thermcap.recorder.storage.reader import read_session_meta

CONFIG = """
[record]
duration = 0.5
fps = 30
width = 80
height = 64
analysis = false
session = "from-config"

[[record.camera]]
name = "left"
source = "sim"

[[record.camera]]
name = "aux"
source = "sim"
width = 40
height = 32
fps = 15
"""


def test_a_config_file_sets_defaults_and_cameras(tmp_path):
    cfg = tmp_path / "thermcap.toml"
    cfg.write_text(CONFIG.replace("[record]\n", f'[record]\nroot = "{tmp_path / "data"}"\n'))
    r = CliRunner().invoke(cli, ["--config", str(cfg), "record", "--json"])
    assert r.exit_code == 0, r.output
    res = json.loads(r.output)
    assert set(res["cameras"]) == {"left", "aux"}
    meta = read_session_meta(tmp_path / "data" / "sessions" / "from-config")
    assert meta["cameras"]["aux"]["sensor"]["resolution"] == {"width": 40, "height": 32}
    assert meta["cameras"]["left"]["sensor"]["resolution"] == {"width": 80, "height": 64}
    # a flag still wins over the file; the environment variable finds the file
    r = CliRunner().invoke(cli, ["record", "--json", "--session", "flag", "--source", "sim"],
                           env={"THERMCAP_CONFIG": str(cfg)})
    assert r.exit_code == 0, r.output
    assert "cameras" not in read_session_meta(tmp_path / "data" / "sessions" / "flag")


def test_config_mistakes_are_named(tmp_path):
    cases = {
        "[record]\nmax-disks = '1G'\n": "[record] has no option 'max-disks'",
        "[recrod]\nfps = 3\n": "[recrod] is not a thermcap command",
        "[record\n": "not valid TOML",
        "[[record.camera]]\nname = 'a'\n": "needs a source",
        "[[record.camera]]\nsource = 'sim'\ncolour = 1\n": "unknown keys colour",
    }
    for text, expect in cases.items():
        cfg = tmp_path / "bad.toml"
        cfg.write_text(text)
        r = CliRunner().invoke(cli, ["--config", str(cfg), "record", "--help"])
        assert r.exit_code == 2, (text, r.output)
        assert str(cfg) in r.output and expect in r.output, r.output
    r = CliRunner().invoke(cli, ["--config", str(tmp_path / "none.toml"), "record", "--help"])
    assert r.exit_code == 2 and "none.toml: no such file" in r.output


class _SlowPublisher:
    """A publisher stuck on a slow network: each frame takes 200 ms."""

    def __init__(self):
        self.frames = 0
        self.url = "ws://test"
        self.viewers = 0

    def add_camera(self, camera, model):
        pass

    def publish_frame(self, *args):
        time.sleep(0.2)
        self.frames += 1

    def publish_event(self, *args):
        pass

    def close(self):
        pass


def test_the_live_branch_never_makes_the_writer_wait():
    """The viewer is stuck (its publish waits until released): the writer's 300 offers still all
    return, the frames the branch cannot hold are dropped and counted, none is lost track of."""
    import threading

    pub = _SlowPublisher()
    release = threading.Event()
    pub.publish_frame = lambda *a: release.wait()  # type: ignore[method-assign]
    branch = LiveBranch(LiveOptions(max_fps=0), publisher=pub)  # type: ignore[arg-type]
    px = np.zeros((512, 640), np.uint16)
    offered = threading.Thread(target=lambda: [branch.offer(None, i, px, i, b"{}") for i in range(300)], daemon=True)
    offered.start()
    offered.join(timeout=60)  # a bound for a failure only: blocked offers would never return
    stuck = offered.is_alive()
    release.set()
    assert not stuck, "the writer's offers waited for a stuck viewer"
    c = branch.counters
    # what is not dropped is in the branch: its queue (depth 2) and the one frame being published
    assert c.offered == 300 and c.dropped >= 300 - 3 and c.published + c.dropped + 3 >= 300
    branch.close()


def test_the_live_branch_keeps_to_its_rate():
    pub = _SlowPublisher()
    pub.publish_frame = lambda *a: None  # type: ignore[method-assign]
    branch = LiveBranch(LiveOptions(max_fps=10), publisher=pub)  # type: ignore[arg-type]
    px = np.zeros((4, 4), np.uint16)
    stop = time.monotonic() + 1.0
    n = 0
    while time.monotonic() < stop:
        branch.offer("a", n, px, n, None)
        n += 1
        time.sleep(0.001)
    branch.close()
    assert 8 <= branch.counters.offered - branch.counters.skipped_for_rate <= 12

