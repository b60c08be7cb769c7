"""Every codec and format id decodes the golden files written by an earlier thermcap, bit-exact.

The files under ``tests/fixture/`` are written once (``python -m tests.fixture.write_golden``) and
never rewritten: a codec or format change that would strand old archives fails here."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from thermcap.archive.archiver import verify_format_dir
from thermcap.archive.codecs import codec_registry, get_codec
from thermcap.archive.formats import format_registry, get_format
from thermcap.archive.manifest import frame_proof, frame_sha256

FIXTURE = Path(__file__).resolve().parents[2] / "fixture"


def _golden(kind: str) -> list[Path]:
    return sorted((FIXTURE / kind).glob("*/golden.json"))


def test_every_registered_id_has_golden_files():
    """A new codec or format is not done until its golden files are committed."""
    assert {p.parent.name for p in _golden("codecs")} == set(codec_registry)
    assert {p.parent.name for p in _golden("formats")} == set(format_registry)


@pytest.mark.parametrize("golden", _golden("codecs"), ids=lambda p: p.parent.name)
def test_codec_decodes_its_golden_file(golden):
    g = json.loads(golden.read_text())
    codec = get_codec(g["config"])
    frame = codec.decode((golden.parent / g["file"]).read_bytes())
    assert list(frame.shape) == g["shape"]
    assert frame.dtype == "uint16"
    assert frame_sha256(frame) == g["sha256"]


@pytest.mark.parametrize("golden", _golden("formats"), ids=lambda p: p.parent.name)
def test_format_reads_its_golden_archive(golden):
    g = json.loads(golden.read_text())
    fmt = get_format(g["config"])
    assert sum(f["frames"] for f in g["files"]) == len(g["sha256"]) == 5
    proof = frame_proof(g)  # the golden archives were written with sha256, and are read so forever
    problems, _ = verify_format_dir(fmt, golden.parent, g["files"], proof, where=golden.parent.name,
                                    times=g["timestamps_ns"])
    assert problems == []
    # random access, as the API reads one frame: the last frame of the second file
    frame = fmt.read_frame(lambda rel: (golden.parent / rel).open("rb"), g["files"], 4)
    assert frame_sha256(frame.pixels) == g["sha256"][4]
    assert proof.of_sidecar(frame.sidecar) == g["sidecar_sha256"][4]
