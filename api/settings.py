"""Service settings, from arguments or the environment (never logged with their secrets). The
variables, their defaults and meanings are declared once, in ``thermcap.recorder.settings``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from thermcap.recorder import settings as env
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["Settings"]


MIN_TOKEN_LENGTH = 8
#: how the examples' placeholders begin (.env.example, the docs): never a token
_PLACEHOLDERS = ("replace-with", "change-me", "changeme", "your-token", "token-here")


def _parse_tokens(text: str) -> dict[str, frozenset[str]]:
    """``token=scopes`` items separated by ``;`` or new lines. Each problem is named on its own,
    by the item's position, never by the token itself (errors may be logged)."""
    tokens: dict[str, frozenset[str]] = {}
    items = [i.strip() for i in text.replace("\n", ";").split(";")]
    for n, item in enumerate((i for i in items if i and not i.startswith("#")), start=1):
        token, _, scopes = item.partition("=")
        token = token.strip()
        scope_set = frozenset(s.strip() for s in (scopes or "read").split(",") if s.strip())
        unknown = scope_set - {"read", "write"}
        if unknown:
            raise ValueError(f"THERMCAP_TOKENS item {n}: unknown scope(s) {sorted(unknown)}; use read and/or write")
        if token.lower().startswith(_PLACEHOLDERS):
            raise ValueError(f"THERMCAP_TOKENS item {n}: a placeholder from an example, not a token; make one "
                             "with `python -c 'import secrets; print(secrets.token_hex(16))'`")
        if len(token) < MIN_TOKEN_LENGTH:
            raise ValueError(f"THERMCAP_TOKENS item {n}: the token is {len(token)} characters; use at least "
                             f"{MIN_TOKEN_LENGTH} (for example "
                             "`python -c 'import secrets; print(secrets.token_hex(16))'`)")
        tokens[token] = scope_set
    return tokens


@dataclass
class Settings:
    root: Path = field(default_factory=lambda: Path(env.ROOT.text()))
    database_url: str | None = field(default_factory=env.DATABASE_URL.get)
    tokens: dict[str, frozenset[str]] = field(default_factory=dict)
    s3_bucket: str | None = field(default_factory=lambda: env.BucketSettings.from_env().bucket)
    s3_endpoint: str | None = field(default_factory=lambda: env.BucketSettings.from_env().endpoint)
    s3_region: str = field(default_factory=lambda: env.BucketSettings.from_env().region)
    s3_prefix: str = field(default_factory=lambda: env.BucketSettings.from_env().prefix)
    cors_origins: list[str] = field(default_factory=lambda: [o for o in (env.CORS_ORIGINS.get() or "").split(",")
                                                             if o])
    # Series jobs on a Dask cluster (the workers reach the same root, index and bucket); none: the
    # API's own threads.
    dask_scheduler: str | None = field(default_factory=env.DASK_SCHEDULER.get)
    zarr_shard_bytes: int = field(default_factory=lambda: int(env.ZARR_SHARD_BYTES.text()))
    max_page_size: int = 1000
    rescan_interval_s: float = 30.0

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        if not self.tokens:
            text = env.TOKENS.text()
            # set means meant, even empty (compose gives '' for a variable the .env lacks): fail closed
            if env.TOKENS.is_set() and not _parse_tokens(text):
                raise ValueError("THERMCAP_TOKENS is set but holds no token (empty, or only comments or "
                                 "separators); refusing to serve without authentication (unset it to serve "
                                 "without tokens on 127.0.0.1)")
            path = env.TOKENS_FILE.get()
            if path:
                from_file = _parse_tokens(Path(path).read_text())
                if not from_file:  # fail closed: a file meant to guard the service never opens it
                    raise ValueError(f"THERMCAP_TOKENS_FILE {path}: holds no token (empty, or only comments); "
                                     f"refusing to serve without authentication")
                text += "\n" + Path(path).read_text()
            self.tokens = _parse_tokens(text)

    @property
    def db_url(self) -> str:
        return self.database_url or f"sqlite:///{DataRoot.of(self.root).index_db.resolve()}"

    def __repr__(self) -> str:  # never print tokens or credentials
        return (f"Settings(root={str(self.root)!r}, db={_redact(self.db_url)!r}, s3={self.s3_bucket!r}, "
                f"tokens={len(self.tokens)})")


def _redact(url: str) -> str:
    if "@" in url and "://" in url:
        scheme, rest = url.split("://", 1)
        return f"{scheme}://***@{rest.split('@', 1)[1]}"
    return url
