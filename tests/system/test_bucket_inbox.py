"""``thermcap watch s3://BUCKET/PREFIX`` against SeaweedFS: each uploaded camera file is taken
once, its derived products land beside it in the bucket, a corrupt one moves to quarantine/
with its reason, and a second watcher with an empty disk takes nothing again (the bucket keeps
the journal)."""

from __future__ import annotations

import json
import os
import shutil

import obstore
from obstore.store import S3Store

from tests.conftest import run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.storage.reader import list_sessions


def test_a_bucket_prefix_is_an_inbox(seaweedfs, tmp_path):
    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=3, paced=False, seed=6), tmp_path / "src",
                   session_id="src", analysis=False)
    assert rec.run().ok
    icd = tmp_path / "icd"
    export_session(rec.session_dir, "icd", icd)
    store = S3Store(seaweedfs["bucket"], endpoint=seaweedfs["endpoint"], region="us-east-1",
                    access_key_id=seaweedfs["AWS_ACCESS_KEY_ID"], secret_access_key=seaweedfs["AWS_SECRET_ACCESS_KEY"],
                    virtual_hosted_style_request=False, client_options={"allow_http": True})
    prefix = f"drop-{tmp_path.name}"
    for p in sorted(icd.iterdir()):
        obstore.put(store, f"{prefix}/field/{p.name}", p.read_bytes())
    obstore.put(store, f"{prefix}/field/broken.jpg", b"\xff\xd8\xff\xe1" + os.urandom(300))
    obstore.put(store, f"{prefix}/field/upload.tmp", b"half")  # a client's temporary name: never taken
    env = {"THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"], "AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
           "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    url = f"s3://{seaweedfs['bucket']}/{prefix}"
    root = tmp_path / "root"
    r = run_cli("watch", url, "--root", str(root), "--once", "--json", "--no-archive", env=env)
    assert r.returncode == 1, r.stderr  # one quarantined
    res = json.loads(r.stdout)
    assert len(res["processed"]) == 3 and set(res["quarantined"]) == {"field/broken.jpg"}
    keys = {m["path"] for batch in obstore.list(store, prefix) for m in batch}
    tiff = next(p["path"] for p in res["processed"])
    assert any(k.startswith(f"{prefix}/{tiff}.derived/") and k.endswith(".png") for k in keys), keys
    quarantined = f"{prefix}/quarantine/field/broken.jpg"
    assert quarantined in keys and quarantined + ".reason.txt" in keys
    assert f"{prefix}/field/broken.jpg" not in keys and f"{prefix}/field/upload.tmp" in keys
    assert len(list_sessions(root)) == 3
    # another host, an empty disk: the bucket's journal says what was taken
    shutil.rmtree(root / ".thermcap")
    other = tmp_path / "root2"
    r = run_cli("watch", url, "--root", str(other), "--once", "--json", "--no-archive", env=env)
    assert r.returncode == 0, r.stderr
    again = json.loads(r.stdout)
    assert again["processed"] == [] and again["quarantined"] == {} and len(again["duplicates"]) == 3
    assert not list_sessions(other)
