"""The one cache policy of every response that may be cached: what may be kept, by whom, and
for how long. Frames and chunks used to carry headers of their own, route by route, and two
promises were forgotten that way: temperatures marked immutable changed with a model version
(a proxy served the old °C), and frames behind a token were marked ``public`` (a shared cache
answered them to anyone).

- Bytes that never change (a frame's counts, an archive file, content-addressed): kept for a
  year, ``immutable``.
- Anything a model version changes (temperatures, previews, the Zarr metadata that names the
  model): ``no-cache``, revalidated against its ETag every time; the ETag is of the bytes, so a
  new version is a new ETag.
- Behind a token (any token configured): ``private``, never in a shared cache; else ``public``.
"""

from __future__ import annotations

from enum import Enum

from starlette.requests import Request

__all__ = ["Kind", "cache_control", "cache_headers"]

_YEAR = 31_536_000


class Kind(Enum):
    FIXED = "fixed"  # counts, archive files: the same bytes forever
    MODEL = "model"  # temperatures and what names the model: revalidated
    LAYOUT = "layout"  # a Zarr 3 shard: its frames depend on the server's shard size and the session's length


def cache_control(kind: Kind, *, guarded: bool) -> str:
    scope = "private" if guarded else "public"
    if kind is Kind.FIXED:
        return f"{scope}, max-age={_YEAR}, immutable"
    return f"{scope}, no-cache"  # MODEL and LAYOUT alike: what the URL holds may change


def cache_headers(request: Request, kind: Kind) -> dict[str, str]:
    """``Cache-Control`` for a response to ``request`` (guarded when the service has tokens)."""
    return {"Cache-Control": cache_control(kind, guarded=bool(request.app.state.settings.tokens))}
