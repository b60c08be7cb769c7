"""DJI temperatures through DJI's own code: the lookup-table model, dji-thermal-cli against the
SDK reference values, and the libdirp ctypes binding against a stand-in library built here."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import subprocess
from pathlib import Path

import httpx
import numpy as np
import pytest
import tifffile

from tests.conftest import ApiServer, run_cli
from thermcap.recorder.importers.dji_sdk import DjiSdkError, LibDirp, find_backend
from thermcap.recorder.radiometry import LookupTableModel, TemperatureUnavailable, model_from_dict

DJI_CLI = shutil.which("dji-thermal-cli")
needs_cli = pytest.mark.skipif(DJI_CLI is None,
                               reason="dji-thermal-cli is not installed (optional, needs Python >= 3.12; "
                                                        ".ci/run installs it where one exists)")


# -- the model ----------------------------------------------------------------------------------

def test_table_from_measurement_is_exact_and_refuses_what_it_does_not_know():
    raw = np.array([[3, 7, 3], [9, 7, 65535]], np.uint16)
    temp = np.array([[1.5, -2.25, 1.5], [30.0, -2.25, 99.0]], np.float32)
    m = LookupTableModel.from_measurement(raw, temp, source="sdk 1", derived_from={"kind": "dji", "layout": "dirp"})
    assert m.counts == (3, 7, 9, 65535)
    assert np.array_equal(m.to_celsius(raw), temp.astype(np.float64))
    with pytest.raises(TemperatureUnavailable, match="count 8 is not in the sdk 1 table"):
        m.to_celsius(np.array([7, 8], np.uint16))
    again = model_from_dict(json.loads(json.dumps(m.to_dict())))
    assert again == m
    assert again.to_dict() == m.to_dict()
    assert m.summary()["entries"] == 4
    assert "counts" not in m.summary()


def test_table_refuses_a_vendor_output_that_is_not_a_per_count_curve():
    raw = np.array([5, 5, 6], np.uint16)
    with pytest.raises(TemperatureUnavailable, match="count 5"):
        LookupTableModel.from_measurement(raw, np.array([1.0, 1.1, 2.0]), source="sdk")
    with pytest.raises(TemperatureUnavailable, match="non-finite"):
        LookupTableModel.from_measurement(raw, np.array([1.0, 1.0, np.nan]), source="sdk")


def test_tables_merge_only_where_they_agree():
    a = LookupTableModel((1, 2), (10.0, 20.0), "sdk", {"layout": "dirp"})
    b = LookupTableModel((2, 3), (20.0, 30.0), "sdk", {"layout": "dirp"})
    assert a.merged(b).counts == (1, 2, 3)
    assert a.merged(LookupTableModel((2,), (20.5,), "sdk", {"layout": "dirp"})) is None
    assert a.merged(LookupTableModel((5,), (1.0,), "other sdk", {"layout": "dirp"})) is None


def test_find_backend_off_and_bad_paths(tmp_path, monkeypatch):
    monkeypatch.delenv("THERMCAP_DJI_SDK", raising=False)
    assert find_backend("off") is None
    with pytest.raises(DjiSdkError, match="no such DJI SDK"):
        find_backend(str(tmp_path / "libdirp.so"))
    (tmp_path / "libdirp.so").write_bytes(b"not a library")
    with pytest.raises(DjiSdkError, match="not a usable DJI libdirp"):
        find_backend(str(tmp_path / "libdirp.so"))
    monkeypatch.setenv("THERMCAP_DJI_SDK", "off")
    assert find_backend("auto") is None


def test_import_cli_names_a_bad_sdk_path_and_writes_nothing(samples, tmp_path):
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), "--root", str(root), "--dji-sdk",
                str(tmp_path / "nope.so"))
    assert r.returncode == 1
    assert "nope.so" in r.stderr
    assert "no such DJI SDK" in r.stderr
    assert not (root / "sessions").exists() or not any((root / "sessions").iterdir())


# -- dji-thermal-cli: the real port of DJI's SDK, against the SDK's own numbers ----------------

@needs_cli
def test_dji_thermal_cli_matches_the_sdk_reference_through_import_archive_and_api(samples, tmp_path):
    ref = json.loads((samples / "dji" / "reference.json").read_text())
    root = tmp_path / "root"
    r = run_cli("import", str(samples / "dji"), "--root", str(root), "--json", "--no-analysis", "--dji-sdk", DJI_CLI,
                timeout=300)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["dji_sdk"].startswith("dji-thermal-cli")
    by_name = {f["path"].rsplit("/", 1)[-1]: f for f in out["files"]}
    assert set(by_name) == set(ref)
    for name, rf in ref.items():
        f, tr = by_name[name], rf["temperature_reference"]
        assert f["raw_sha256"] == rf["raw_sha256"], name  # the counts never change
        assert f["model"]["kind"] == "lookup_table"
        assert f["model"]["derived_from"]["layout"] == rf["layout"]
        for ours, theirs in ((f["celsius"]["min"], tr["min_C"]), (f["celsius"]["max"], tr["max_C"]),
                             (f["celsius"]["mean"], tr["mean_C"])):
            assert abs(ours - theirs) < 0.1, (name, ours, theirs)
        assert "approximate" not in f["celsius"]
    assert run_cli("archive", "--all", "--root", str(root), "--formats", "png16").returncode == 0
    server = ApiServer(root)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            for name, rf in ref.items():
                sid = by_name[name]["session_id"]
                raw = c.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"}).content
                assert hashlib.sha256(raw).hexdigest() == rf["raw_sha256"]
                t = tifffile.imread(io.BytesIO(c.get(f"/api/v1/sessions/{sid}/frames/0",
                                                     params={"format": "celsius-tiff"}).content))
                for y, x, v in rf["temperature_reference"]["pixels_row_col_C"]:
                    assert abs(float(t[y, x]) - v) < 0.1, (name, y, x, float(t[y, x]), v)
                y, x, v = rf["temperature_reference"]["pixels_row_col_C"][1]
                px = c.get(f"/api/v1/sessions/{sid}/frames/0/temperature", params={"x": x, "y": y}).json()
                assert abs(px["celsius"] - v) < 0.1
                assert px["approximate"] is False
    finally:
        server.stop()


@needs_cli
def test_one_cameras_frames_share_a_session_and_its_merged_table(samples, tmp_path):
    """A survey: many shots from one camera land in one session, the tables merged (here the same
    H20T shot twice under two names, and an M2EA shot that must stay apart)."""
    src = tmp_path / "flight"
    src.mkdir()
    shutil.copy(samples / "dji" / "DJI_H20T.jpg", src / "a.jpg")
    shutil.copy(samples / "dji" / "DJI_H20T.jpg", src / "b.jpg")
    shutil.copy(samples / "dji" / "M2EA_DJI_0001_R.JPG", src / "c.jpg")
    r = run_cli("import", str(src), "--root", str(tmp_path / "r"), "--json", "--no-analysis", "--dji-sdk", DJI_CLI,
                timeout=300)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert sorted(s["frames_written"] for s in out["sessions"]) == [1, 2]
    sids = {f["path"].rsplit("/", 1)[-1]: f["session_id"] for f in out["files"]}
    assert sids["a.jpg"] == sids["b.jpg"] != sids["c.jpg"]


def test_without_an_sdk_dirp_has_no_temperature_and_says_why(samples, tmp_path):
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), "--root", str(tmp_path / "r"), "--json",
                "--no-analysis", "--dji-sdk", "off")
    assert r.returncode == 0, r.stderr
    (f,) = json.loads(r.stdout)["files"]
    assert f["celsius"] is None
    assert "DJI Thermal SDK" in f["celsius_unavailable"]
    assert f["model"]["kind"] == "dji"


# -- libdirp through ctypes, against a stand-in built from DJI's published header ---------------

FAKE_DIRP = r"""
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
typedef void *DIRP_HANDLE;
typedef struct { int32_t width; int32_t height; } dirp_resolution_t;
static int live = 0;
static int32_t last_size = 0;
int32_t dirp_create_from_rjpeg(const uint8_t *data, int32_t size, DIRP_HANDLE *ph) {
    last_size = size;
    if (size < 4 || data[0] != 0xFF || data[1] != 0xD8) return -2;   /* DIRP_ERROR_INVALID_PARAMS-like */
    if (getenv("FAKE_DIRP_REJECT")) return -9;
    *ph = malloc(16); live++; return 0;
}
int32_t dirp_get_rjpeg_resolution(DIRP_HANDLE h, dirp_resolution_t *r) { r->width = 640; r->height = 512; return 0; }
int32_t dirp_measure_ex(DIRP_HANDLE h, float *t, int32_t size) {
    if (size != 640 * 512 * 4) return -3;                                /* wrong buffer size */
    for (int i = 0; i < 640 * 512; i++)
        t[i] = getenv("FAKE_DIRP_NOISY") ? (float)i : getenv("FAKE_DIRP_BY_SIZE") ? 20.0f + last_size % 7 : 21.5f;
    return 0;
}
int32_t dirp_destroy(DIRP_HANDLE h) { free(h); live--; return 0; }
int32_t fake_live_handles(void) { return live; }
"""


@pytest.fixture(scope="module")
def fake_libdirp(tmp_path_factory) -> Path:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler to build the stand-in libdirp")
    d = tmp_path_factory.mktemp("dirp")
    (d / "fake_dirp.c").write_text(FAKE_DIRP)
    subprocess.run([cc, "-shared", "-fPIC", "-O1", "-o", str(d / "libdirp.so"), str(d / "fake_dirp.c")], check=True)
    return d / "libdirp.so"


def test_libdirp_binding_passes_the_buffer_and_frees_every_handle(samples, fake_libdirp):
    import ctypes

    sdk = LibDirp(str(fake_libdirp))
    path = str(samples / "dji" / "DJI_H20T.jpg")
    out = sdk.measure([path, path])
    assert out[path].shape == (512, 640)
    assert out[path].dtype == np.float32
    assert np.all(out[path] == 21.5)
    assert ctypes.CDLL(str(fake_libdirp)).fake_live_handles() == 0
    text = str(samples / "flir" / "FLIR_E40.exiftool.txt")  # not a JPEG: the SDK refuses, we say so
    assert "dirp_create_from_rjpeg returned -2" in sdk.measure([text])[text]


def test_import_with_libdirp_path_uses_it_and_reports_its_refusals(samples, fake_libdirp, tmp_path):
    h20t = str(samples / "dji" / "DJI_H20T.jpg")
    r = run_cli("import", h20t, "--root", str(tmp_path / "a"), "--json", "--no-analysis", "--dji-sdk",
                str(fake_libdirp))
    assert r.returncode == 0, r.stderr
    (f,) = json.loads(r.stdout)["files"]
    assert f["celsius"] == {"min": 21.5, "max": 21.5, "mean": 21.5}
    assert "libdirp" in f["model"]["source"]
    # the SDK refuses the file: imported all the same (the counts are fine), without a temperature
    r = run_cli("import", h20t, "--root", str(tmp_path / "b"), "--json", "--no-analysis", "--dji-sdk",
                str(fake_libdirp),
                env={"FAKE_DIRP_REJECT": "1"})
    assert r.returncode == 0, r.stderr
    (f,) = json.loads(r.stdout)["files"]
    assert f["celsius"] is None
    assert "returned -9" in f["dji_sdk_error"]
    # an output that is not a function of the count is not turned into a table
    r = run_cli("import", h20t, "--root", str(tmp_path / "c"), "--json", "--no-analysis", "--dji-sdk",
                str(fake_libdirp),
                env={"FAKE_DIRP_NOISY": "1"})
    (f,) = json.loads(r.stdout)["files"]
    assert f["celsius"] is None
    assert "not a per-count curve" in f["dji_sdk_error"]


@needs_cli
def test_h20t_exports_sdk_temperatures_as_a_geotiff(samples, tmp_path):
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), "--root", str(root), "--session", "h20t",
                "--no-analysis", "--dji-sdk", DJI_CLI)
    assert r.returncode == 0, r.stderr
    r = run_cli("export", "h20t", "--root", str(root), "--to", "celsius-tiff", "--out", str(tmp_path / "t"))
    assert r.returncode == 0, r.stderr
    ref = json.loads((samples / "dji" / "reference.json").read_text())["DJI_H20T.jpg"]["temperature_reference"]
    with tifffile.TiffFile(next((tmp_path / "t").glob("*.tif*"))) as t:
        img = t.pages[0].asarray()
        assert t.pages[0].geotiff_tags["GeographicTypeGeoKey"] == 4326  # the drone-dji XMP position
    for y, x, v in ref["pixels_row_col_C"]:
        assert abs(float(img[y, x]) - v) < 0.1


def test_api_lists_a_table_by_identity_and_serves_it_whole_on_the_session(samples, fake_libdirp, tmp_path):
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji" / "M30T_DJI_0003_R.JPG"), "--root", str(root), "--session", "girp",
                "--no-analysis", "--dji-sdk", str(fake_libdirp))
    assert r.returncode == 0, r.stderr
    assert run_cli("archive", "--all", "--root", str(root), "--formats", "png16").returncode == 0
    server = ApiServer(root)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            (item,) = c.get("/api/v1/sessions").json()["items"]
            listed = item["radiometric_model"]
            assert listed["kind"] == "lookup_table"
            assert "counts" not in listed
            assert listed["entries"] > 100
            assert listed["derived_from"]["layout"] == "girp"
            full = c.get("/api/v1/sessions/girp").json()["radiometric_model"]
            assert len(full["counts"]) == listed["entries"]
            assert set(full["celsius"]) == {21.5}
            px = c.get("/api/v1/sessions/girp/frames/0/temperature", params={"x": 5, "y": 7}).json()
            assert px["celsius"] == 21.5
            assert px["model"]["table_sha256"] == listed["table_sha256"]
        chromium = shutil.which("chromium") or shutil.which("chromium-browser")
        if chromium:  # the browser view names the table instead of printing it
            from tests.system.api.test_schema_and_browser import CHROMIUM_FLAGS

            dom = subprocess.run([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom",
                                  f"{server.url}/ui/sessions/girp"], capture_output=True, text=True, timeout=120).stdout
            assert 'data-ready="1"' in dom, dom[-1500:]
            assert f"lookup table, {listed['entries']} counts" in dom, dom[-1500:]
            assert "/frames/0?format=dji-rjpeg" in dom  # a DJI session offers the rebuilt R-JPEG
    finally:
        server.stop()


# -- years later: R-JPEGs rebuilt from the archive, for DJI's own tools -------------------------

def _import_and_rebuild(samples, tmp_path) -> tuple[dict, Path]:
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji"), "--root", str(root), "--json", "--no-analysis", "--dji-sdk", "off")
    assert r.returncode == 0, r.stderr
    files = {f["path"].rsplit("/", 1)[-1]: f for f in json.loads(r.stdout)["files"]}
    out = tmp_path / "rebuilt"
    for sid in {f["session_id"] for f in files.values()}:
        r = run_cli("export", sid, "--root", str(root), "--to", "dji-rjpeg", "--out", str(out))
        assert r.returncode == 0, r.stderr
    return files, out


def test_rebuilt_rjpegs_carry_the_frame_and_every_segment_bit_exact(samples, tmp_path):
    from thermcap.recorder.importers import read_file
    from thermcap.recorder.importers.dji import SEGMENTS_BLOB

    files, out = _import_and_rebuild(samples, tmp_path)
    assert sorted(p.name for p in out.iterdir()) == sorted(files)
    for name, f in files.items():
        (orig,) = read_file(samples / "dji" / name)
        (again,) = read_file(out / name)
        assert hashlib.sha256(again.pixels.astype("<u2").tobytes()).hexdigest() == f["raw_sha256"]
        assert again.layout == orig.layout
        assert again.blobs == orig.blobs  # APP4, APP5, EXIF, XMP, APP7 ...
        assert SEGMENTS_BLOB in again.blobs


@needs_cli
def test_dji_tools_measure_rebuilt_rjpegs_exactly_as_the_originals(samples, tmp_path):
    _files, out = _import_and_rebuild(samples, tmp_path)
    measure = find_backend(DJI_CLI).measure
    originals = measure([str(samples / "dji" / p.name) for p in sorted(out.iterdir())])
    rebuilt = measure([str(p) for p in sorted(out.iterdir())])
    for p in sorted(out.iterdir()):
        assert np.array_equal(rebuilt[str(p)], originals[str(samples / "dji" / p.name)]), p.name


def test_api_serves_the_rebuilt_rjpeg_after_the_mcap_source_is_deleted(samples, tmp_path):
    from thermcap.recorder.importers import read_file

    files, rebuilt = _import_and_rebuild(samples, tmp_path)
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "flir" / "FLIR_E40.jpg"), "--root", str(root), "--session", "flir",
                "--no-analysis")
    assert r.returncode == 0, r.stderr
    r = run_cli("archive", "--all", "--root", str(root), "--formats", "png16", "--delete-source")
    assert r.returncode == 0, r.stderr
    assert not list(root.glob("sessions/*/*.mcap"))  # only the archive and its extras.mcap remain
    server = ApiServer(root)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            for name, f in files.items():
                resp = c.get(f"/api/v1/sessions/{f['session_id']}/frames/0", params={"format": "dji-rjpeg"})
                assert resp.status_code == 200
                assert name in resp.headers["content-disposition"]
                assert resp.content == (rebuilt / name).read_bytes()  # the same file export wrote
                out = tmp_path / name
                out.write_bytes(resp.content)
                (again,) = read_file(out)
                (orig,) = read_file(samples / "dji" / name)
                assert np.array_equal(again.pixels, orig.pixels)
                assert again.blobs == orig.blobs
            r = c.get("/api/v1/sessions/flir/frames/0", params={"format": "dji-rjpeg"})
            assert r.status_code == 404
            assert "dji_rjpeg_segments.bin" in r.json()["error"]
    finally:
        server.stop()


def test_frames_whose_sdk_tables_disagree_get_separate_sessions(samples, fake_libdirp, tmp_path):
    """Same camera, same counts, different temperatures (here: the stand-in answers by file size):
    one table cannot hold both, so they are two sessions, each with its own."""
    src = tmp_path / "in"
    src.mkdir()
    data = (samples / "dji" / "DJI_H20T.jpg").read_bytes()
    (src / "a.jpg").write_bytes(data)
    (src / "b.jpg").write_bytes(data)
    (src / "c.jpg").write_bytes(data + b"\0")  # one byte after the image: a different answer
    r = run_cli("import", str(src), "--root", str(tmp_path / "r"), "--json", "--no-analysis", "--dji-sdk",
                str(fake_libdirp), env={"FAKE_DIRP_BY_SIZE": "1"})
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    sids = {f["path"].rsplit("/", 1)[-1]: f["session_id"] for f in out["files"]}
    assert sids["a.jpg"] == sids["b.jpg"] != sids["c.jpg"]
    temps = {f["path"].rsplit("/", 1)[-1]: f["celsius"]["mean"] for f in out["files"]}
    assert temps["a.jpg"] == temps["b.jpg"] != temps["c.jpg"]
