"""Errors of the API package, and the answer each one becomes.

LookupError
 +-- FrameNotFound        no such session frame or attachment                      -> 404
 +-- FrameUnavailable     every copy of the frame is missing or damaged            -> 503
recorder.radiometry.TemperatureUnavailable   the model needs a vendor SDK          -> 409
fastapi.HTTPException     bad requests (cursor, range, path, scope)                -> 4xx as raised

The handlers live in ``api.app``; routes raise, never build error responses themselves.
"""

from __future__ import annotations

__all__ = ["FrameNotFound", "FrameUnavailable"]


class FrameNotFound(LookupError):
    """The session has no such frame (or the frame no such attachment)."""


class FrameUnavailable(LookupError):
    """Every copy of a frame is missing or damaged (each was checked against the manifest)."""
