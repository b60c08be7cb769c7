"""A session's frames read back from its archive, once the MCAP source is deleted.

Every archive format is a full source: ``archived_frames`` gives the same ``SessionFrame``
stream (counts, sidecar exactly as recorded, time, segment name) as the MCAP reader did, from
the first verified format on disk, so ``analyze``, exports and re-archiving work after
``--delete-source``. The ``thermcap`` facade registers it with ``recorder.storage.archive_readers``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from thermcap.archive.exceptions import ManifestError, VerificationError
from thermcap.archive.formats import get_format, read_cost
from thermcap.archive.manifest import frame_proof, load_manifest
from thermcap.archive.manifest_types import Manifest
from thermcap.archive.reading.copies import differs, wanted
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.reader import SessionFrame

__all__ = ["archived_frames", "frames_from_format", "verified_formats"]


def verified_formats(manifest: Manifest, layout: SessionLayout, *, but: str | None = None) -> list[str]:
    """Verified formats that scrub has not marked damaged and whose folder is on disk (other than
    ``but``), cheapest to read whole first (their declared ``ReadCost``): the copies any reader,
    or a repair, may take every frame from."""
    fmts = [f for f, e in manifest.get("formats", {}).items() if f != but and e.get("verified") and e.get("files")
            and not e.get("damaged") and layout.format_dir(f).is_dir()]
    return sorted(fmts, key=lambda f: (read_cost(f).stream, f))


def archived_frames(session_dir: Path) -> Iterator[SessionFrame] | None:
    """The session's frames from its archive; None when it has no verified archive on disk."""
    layout = SessionLayout.of(session_dir)
    try:
        manifest = load_manifest(layout.dir, required=False)
    except ManifestError:
        return None
    if manifest is None:
        return None
    fmts = verified_formats(manifest, layout)
    if not fmts:
        return None
    return frames_from_format(manifest, layout, fmts[0])


def frames_from_format(manifest: Manifest, layout: SessionLayout, fid: str) -> Iterator[SessionFrame]:
    """The session's frames as format ``fid`` gives them back (with the manifest's segment names).

    Each frame's pixels and sidecar are checked against the manifest's hashes as they are read: a
    copy damaged since scrub last looked raises here, naming the frame, instead of handing damaged
    counts to an analysis or an export."""
    entry = manifest["formats"][fid]
    fmt = get_format(entry.get("config") or fid)
    frames = manifest.get("frames", {})
    segments = frames.get("segments") or []
    times = frames.get("timestamps_ns") or []
    proof = frame_proof(frames)
    for i, decoded in enumerate(fmt.read(layout.format_dir(fid), [r["path"] for r in entry["files"]])):
        if differs("pixels", decoded.pixels, wanted(proof, i, "pixels"), proof.name) or \
                differs("sidecar", decoded.sidecar, wanted(proof, i, "sidecar"), proof.name):
            raise VerificationError(f"{layout.format_dir(fid)}: frame {i} differs from the manifest; "
                                    f"run `thermcap scrub {layout.dir.parents[1]} --repair`")
        log_time = decoded.log_time if decoded.log_time is not None else (times[i] if i < len(times) else 0)
        segment = segments[i] if i < len(segments) else ""
        yield SessionFrame(i, segment, log_time, decoded.pixels, decoded.sidecar)
