"""Frames answer HEAD with the same headers as GET, carry a strong ETag (304 on a match), and
``serve --get`` writes a binary body byte for byte."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from thermcap.cli import cli
from thermcap.recorder.storage.reader import iter_session_frames


@pytest.mark.parametrize("fmt", ["png16", "raw", "tiff", "celsius-tiff", "preview"])
@pytest.mark.parametrize("sid", ["s-archived", "s-mcap-only"])
def test_head_and_etag(client, sid, fmt):
    url = f"/api/v1/sessions/{sid}/frames/3?format={fmt}"
    get = client.get(url)
    assert get.status_code == 200
    etag = get.headers["etag"]
    assert etag.startswith('"') and etag.endswith('"') and len(etag) > 10
    head = client.head(url)
    assert head.status_code == 200 and head.content == b""
    assert head.headers["etag"] == etag and head.headers["content-length"] == str(len(get.content))
    assert head.headers["content-type"] == get.headers["content-type"]
    again = client.get(url, headers={"If-None-Match": etag})
    assert again.status_code == 304 and again.content == b""
    assert client.get(url, headers={"If-None-Match": '"other"'}).status_code == 200
    other = client.get(f"/api/v1/sessions/{sid}/frames/4?format={fmt}")
    assert other.headers["etag"] != etag


def test_serve_get_writes_binary_unmangled(root, tmp_path):
    r = CliRunner().invoke(cli, ["serve", "--root", str(root), "--get",
                                 "/api/v1/sessions/s-archived/frames/2?format=raw"])
    assert r.exit_code == 0
    frame = [f for f in iter_session_frames(root / "sessions" / "s-archived")][2]
    assert r.stdout_bytes == np.ascontiguousarray(frame.pixels).astype("<u2").tobytes()
