"""Errors of the API package, and the answer each one becomes.

LookupError
 +-- FrameNotFound        no such session frame or attachment                      -> 404
 +-- FrameUnavailable     every copy of the frame is missing or damaged            -> 503
recorder.radiometry.TemperatureUnavailable   the model needs a vendor SDK          -> 409
fastapi.HTTPException     bad requests (cursor, range, path, scope)                -> 4xx as raised

The handlers live in ``api.app``; routes raise, never build error responses themselves.
"""

from __future__ import annotations

from thermcap.archive.exceptions import FrameNotFound, FrameUnavailable

__all__ = ["FrameNotFound", "FrameUnavailable"]  # raised by the archive's reader of verified copies
