"""Issue 63: a ROS 2 bag (MCAP storage) with a mono16 camera, written by the rosbags library as
`ros2 bag record` writes it, imports as a session: its header stamps as capture times, its log
times and CameraInfo kept, counts bit-exact against rosbags' own reader; then it archives and
is served like any session."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import run_cli
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

W, H, N = 40, 30, 12
T0 = 1_700_000_000_000_000_000


def _write_bag(path, *, extra_mono16_topic: bool = False, big_endian_every: int = 0, storage: str = "mcap") -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    Image, Info = ts.types["sensor_msgs/msg/Image"], ts.types["sensor_msgs/msg/CameraInfo"]
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    RoI = ts.types["sensor_msgs/msg/RegionOfInterest"]
    rng = np.random.default_rng(5)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        img = w.add_connection("/flir_boson/image_raw", Image.__msgtype__, typestore=ts)
        info = w.add_connection("/flir_boson/camera_info", Info.__msgtype__, typestore=ts)
        other = w.add_connection("/mast/image_raw", Image.__msgtype__, typestore=ts) if extra_mono16_topic else None
        for i in range(N):
            stamp = T0 + i * 33_333_333
            header = Header(stamp=Time(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="boson")
            counts = rng.integers(0, 2**14, (H, W), dtype=np.uint16)
            big = bool(big_endian_every and i % big_endian_every == 0)
            row = counts.astype(">u2" if big else "<u2").view(np.uint8).reshape(H, 2 * W)
            padded = np.zeros((H, 2 * W + 8), np.uint8)  # rows with padding: step > 2 * width
            padded[:, :2 * W] = row
            msg = Image(header=header, height=H, width=W, encoding="mono16", is_bigendian=int(big),
                        step=2 * W + 8, data=padded.ravel())
            log_time = stamp + 2_000_000  # the bag's own clock: when the recorder got it
            if i % 4 == 0:
                cam = Info(header=header, height=H, width=W, distortion_model="plumb_bob",
                           d=np.zeros(5), k=np.array([500.0, 0, W / 2, 0, 500.0, H / 2, 0, 0, 1]),
                           r=np.eye(3).ravel(), p=np.zeros(12), binning_x=0, binning_y=0,
                           roi=RoI(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
                w.write(info, log_time - 1, ts.serialize_cdr(cam, Info.__msgtype__))
            w.write(img, log_time, ts.serialize_cdr(msg, Image.__msgtype__))
            if other is not None:
                w.write(other, log_time, ts.serialize_cdr(msg, Image.__msgtype__))


def _rosbags_counts(path) -> list[tuple[int, int, np.ndarray]]:
    """(header stamp, log time, counts) per image, read by rosbags itself."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == "/flir_boson/image_raw"]
        for conn, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            rows = np.asarray(msg.data, np.uint8).reshape(msg.height, msg.step)[:, :2 * msg.width]
            counts = np.ascontiguousarray(rows).view(">u2" if msg.is_bigendian else "<u2").astype(np.uint16)
            out.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, log_time, counts))
    return out


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_ros2_bag_imports_bit_exact_with_its_own_times(tmp_path, storage):
    bag = tmp_path / "drive"
    _write_bag(bag, big_endian_every=3, storage=storage)
    want = _rosbags_counts(bag)
    root = tmp_path / "root"
    r = run_cli("import", str(bag), "--root", str(root), "--session", "bag", "--json")
    assert r.returncode == 0, r.stderr
    frames = list(iter_session_frames(root / "sessions" / "bag"))
    assert len(frames) == N == len(want)
    for f, (stamp, _, counts) in zip(frames, want, strict=True):
        assert f.log_time == stamp  # the camera's header stamp is the frame's time
        assert np.array_equal(f.pixels, counts)
    # the bag's log times, its CameraInfo and its metadata.yaml are kept
    from mcap.reader import make_reader

    seg = sorted((root / "sessions" / "bag").glob("*.mcap"))[0]
    with open(seg, "rb") as fh:
        reader = make_reader(fh)
        sources = [json.loads(json_payload(c.message_encoding, m.data))
                   for _, c, m in reader.iter_messages(topics=["/import/source"])]
        attachments = [a.name for a in reader.iter_attachments()]
    assert [s["vendor"]["log_time_ns"] for s in sources] == [t for _, t, _ in want]
    assert storage == "sqlite3" or "publish_time_ns" in sources[0]["vendor"]  # a .db3 keeps no publish time
    assert sources[1]["vendor"]["camera_info"]["k"][0] == 500.0
    assert "assumed" in sources[0]["vendor"]["radiometric_model"]
    assert any(a.endswith("metadata.yaml") for a in attachments), attachments
    # and it is a session like any other: archived, verified, listed
    assert run_cli("archive", "bag", "--root", str(root), "--formats", "png16").returncode == 0
    assert run_cli("verify", "bag", "--root", str(root)).returncode == 0


def test_a_bag_with_two_cameras_is_refused_naming_them(tmp_path):
    bag = tmp_path / "two"
    _write_bag(bag, extra_mono16_topic=True)
    r = run_cli("import", str(bag), "--root", str(tmp_path / "root"), "--session", "two")
    assert r.returncode != 0 and "/mast/image_raw" in (r.stdout + r.stderr) and "Traceback" not in r.stderr


def test_a_bag_takes_the_cameras_model_from_the_command_line(tmp_path):
    """A bag carries no radiometric model: ``--model`` gives the camera's (a Lepton in TLinear mode,
    centikelvin), the session holds it and each frame's import record says where it came from."""
    bag = tmp_path / "lepton"
    _write_bag(bag)
    lepton = {"kind": "linear", "scale_c_per_count": 0.01, "offset_c": -273.15, "bit_depth": 16}
    root = tmp_path / "root"
    r = run_cli("import", str(bag), "--root", str(root), "--session", "lep", "--model", json.dumps(lepton))
    assert r.returncode == 0, r.stderr
    meta = json.loads((root / "sessions" / "lep" / "session.json").read_text())
    assert meta["radiometric_model"] == lepton
    from mcap.reader import make_reader

    with open(sorted((root / "sessions" / "lep").glob("*.mcap"))[0], "rb") as fh:
        first = next(make_reader(fh).iter_messages(topics=["/import/source"]))
        assert "given on import" in json.loads(json_payload(first[1].message_encoding, first[2].data))[
            "vendor"]["radiometric_model"]
    bad = run_cli("import", str(bag), "--root", str(root), "--model", '{"kind": "linear", "gain": 2}')
    assert bad.returncode != 0 and "--model" in bad.stderr and "Traceback" not in bad.stderr, bad.stderr


def test_a_bag_copied_under_sessions_is_named_not_hidden(tmp_path):
    """`ls` said `unreadable` and the index passed the bag over in silence: both now say what it is
    and how to make it a session."""
    root = tmp_path / "root"
    _write_bag(root / "sessions" / "drive")
    ls = run_cli("ls", "--root", str(root))
    assert "ros2-bag" in ls.stdout and "thermcap import" in ls.stdout, ls.stdout
    index = run_cli("index", "--root", str(root))
    assert "ROS 2 bag" in index.stderr and "thermcap import" in index.stderr, index.stderr
