"""Reading a session's frames back, from whichever copy verifies.

- ``copies``: the one place a frame is taken from a copy and checked against the manifest;
- ``whole``: every frame in order from one verified archive format, once the source is deleted;
- ``numbering``: the session's one numbering of its frames (the manifest's table, checked
  against the session's ledger), with each frame's sidecar from the cheapest copy that has it;
- ``folder``: a session folder's frames, read without writing anything;
- ``mcap_frames``, ``zip_directory``, ``frame_table``: the pieces the readers share.
"""

from thermcap.archive.reading.whole import archived_frames, frames_from_format, verified_formats

__all__ = ["archived_frames", "frames_from_format", "verified_formats"]
