"""Samples -> import -> archive -> API: bit-exact counts and the right temperatures."""

from __future__ import annotations

import io
import json

import httpx
import tifffile
from mcap.reader import make_reader

from tests.conftest import ApiServer, run_cli
from thermcap.recorder.importers.jpeg import app_segments, concat_app


def test_samples_import_archive_and_serve(samples, tmp_path):
    root = tmp_path / "root"
    r = run_cli("import", str(samples), "--root", str(root), "--json", "--no-analysis", "--dji-sdk", "off")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    ref_flir = json.loads((samples / "flir" / "reference.json").read_text())
    ref_dji = json.loads((samples / "dji" / "reference.json").read_text())
    by_name = {f["path"].rsplit("/", 1)[-1]: f for f in out["files"]}
    for name, ref in {**ref_flir, **ref_dji}.items():
        assert by_name[name]["raw_sha256"] == ref["raw_sha256"], name
    assert by_name["DJI_H20T.jpg"]["celsius"] is None
    assert "SDK" in by_name["DJI_H20T.jpg"]["celsius_unavailable"]
    assert by_name["M2EA_DJI_0001_R.JPG"]["celsius"]["approximate"] is True
    # calibration blobs ride along as attachments, bit-exact
    h20t = by_name["DJI_H20T.jpg"]["session_id"]
    seg = next((root / "sessions" / h20t).glob("*.mcap"))
    with open(seg, "rb") as f:
        atts = {a.name: a.data for a in make_reader(f).iter_attachments()}
    segs = app_segments("x", (samples / "dji" / "DJI_H20T.jpg").read_bytes())
    assert atts["DJI_H20T.jpg/dji_app5_calibration.bin"] == concat_app(segs, 0xE5)
    e40 = by_name["FLIR_E40.jpg"]["session_id"]
    r = run_cli("archive", "--all", "--root", str(root), "--formats", "png16")
    assert r.returncode == 0, r.stderr
    server = ApiServer(root)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            t = tifffile.imread(io.BytesIO(c.get(f"/api/v1/sessions/{e40}/frames/0",
                                                 params={"format": "celsius-tiff"}).content))
            tr = ref_flir["FLIR_E40.jpg"]["temperature_reference"]
            for y, x, v in tr["pixels_row_col_C"]:
                assert abs(t[y, x] - v) < 0.01
            raw = c.get(f"/api/v1/sessions/{h20t}/frames/0", params={"format": "raw"}).content
            import hashlib

            assert hashlib.sha256(raw).hexdigest() == ref_dji["DJI_H20T.jpg"]["raw_sha256"]
            r = c.get(f"/api/v1/sessions/{h20t}/frames/0", params={"format": "celsius-tiff"})
            assert r.status_code == 409
            assert "DJI Thermal SDK" in r.json()["error"]
            assert c.get(f"/api/v1/sessions/{h20t}/frames/0", params={"format": "preview"}).status_code == 200
    finally:
        server.stop()
