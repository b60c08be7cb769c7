"""``thermcap.open``: a session from wherever it is, as a ``Session``."""

from __future__ import annotations

import os
import re
from pathlib import Path

from thermcap.session import LocalSession, Session

__all__ = ["open"]

_SESSION_URL = re.compile(r"^(?P<base>https?://.+?)/api/v1/sessions/(?P<id>[^/?#]+)/?$")


def open(where: str | os.PathLike[str], token: str | None = None, *, root: str | os.PathLike[str] | None = None
         ) -> Session:
    """A session: a session folder, an id under ``root`` (default ``THERMCAP_ROOT`` or
    ``thermcap-data``), an ``http(s)://HOST/api/v1/sessions/ID`` URL with the server's token, or
    an uploaded archive, ``s3://BUCKET[/PREFIX]/sessions/ID`` (its endpoint from
    ``THERMCAP_S3_ENDPOINT``, credentials from ``AWS_ACCESS_KEY_ID`` / ``AWS_SECRET_ACCESS_KEY``).

    Raises ``FileNotFoundError`` naming what was looked for when there is no such session.
    """
    text = os.fspath(where)
    m = _SESSION_URL.match(text)
    if m:
        from thermcap.client import Client
        from thermcap.remote import RemoteSession

        return RemoteSession(Client(m.group("base"), token), m.group("id"))
    if text.startswith(("http://", "https://")):
        raise ValueError(f"{text}: a session URL looks like http://HOST:PORT/api/v1/sessions/ID")
    if text.startswith("s3://"):
        from thermcap.bucket import open_bucket_session

        return open_bucket_session(text)
    if "://" in text:
        raise ValueError(f"{text}: thermcap.open reads folders, ids under a root, http(s) session URLs and "
                         f"s3://BUCKET/sessions/ID")
    from thermcap.recorder.storage.layout import SESSIONS_DIR, DataRoot, SessionLayout

    path = Path(text)
    if SessionLayout.of(path).session_json.is_file():
        session_dir = path.resolve()
        if session_dir.parent.name != SESSIONS_DIR:
            raise ValueError(f"{path}: not inside a data root (ROOT/sessions/ID); move it there or import it")
        return LocalSession(session_dir, session_dir.parent.parent)
    from thermcap.recorder.cli.options import default_root

    base = Path(root) if root is not None else Path(default_root())
    if os.sep in text or (os.altsep and os.altsep in text):
        raise FileNotFoundError(f"{path}: no session here (no session.json)")
    layout = SessionLayout.of(DataRoot.of(base).session(text).dir.resolve())
    session_dir = layout.dir
    if not layout.session_json.is_file():
        raise FileNotFoundError(f"no session {text!r} under {base} (looked for {layout.session_json})")
    return LocalSession(session_dir, session_dir.parent.parent)

