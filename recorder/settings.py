"""Every environment variable thermcap reads, declared once: its name, its default and what it
means. Commands, the service and the Python API read them through these declarations (a click
option's ``envvar=S3_BUCKET.name``, ``BucketSettings.from_env()``), so a default cannot differ
between two readers of one variable, and the reference page lists exactly these
(``tests/unit/meta/test_one_settings.py`` holds both)."""

from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = ["VARIABLES", "BucketSettings", "Variable"]


@dataclass(frozen=True)
class Variable:
    name: str
    default: str | None
    meaning: str

    def get(self) -> str | None:
        return os.environ.get(self.name, self.default)

    def text(self) -> str:
        """Its value where set and not empty, else its default ("" where it has none)."""
        return os.environ.get(self.name) or self.default or ""

    def is_set(self) -> bool:
        """Set, even to an empty string (compose gives '' for a variable its .env lacks)."""
        return self.name in os.environ


ROOT = Variable("THERMCAP_ROOT", "thermcap-data", "the data root of every command and the service")
CONFIG = Variable("THERMCAP_CONFIG", None, "a TOML file of command defaults (`--config`)")
DATABASE_URL = Variable("THERMCAP_DATABASE_URL", None,
                        "the index's SQLAlchemy URL (default: SQLite in the data root)")
TOKENS = Variable("THERMCAP_TOKENS", None, 'the service\'s tokens, "token=read,write;other=read"')
TOKENS_FILE = Variable("THERMCAP_TOKENS_FILE", None, 'a file of tokens, one "token=scopes" a line')
CONTROL_TOKEN = Variable("THERMCAP_CONTROL_TOKEN", None, "the recorder's control token (`record --control`, `ctl`)")
S3_BUCKET = Variable("THERMCAP_S3_BUCKET", None, "the bucket archives are uploaded to, served from and synced to")
S3_ENDPOINT = Variable("THERMCAP_S3_ENDPOINT", None, "an S3-compatible endpoint (SeaweedFS, MinIO, R2)")
S3_REGION = Variable("THERMCAP_S3_REGION", "us-east-1", "the bucket's region")
S3_PREFIX = Variable("THERMCAP_S3_PREFIX", "", "a key prefix inside the bucket")
CORS_ORIGINS = Variable("THERMCAP_CORS_ORIGINS", "*", "comma-separated origins CORS allows to read")
DASK_SCHEDULER = Variable("THERMCAP_DASK_SCHEDULER", None, "a Dask scheduler for the fleet's jobs (tcp://HOST:8786)")
HEAD_TIMEOUT_S = Variable("THERMCAP_HEAD_TIMEOUT_S", "30", "seconds a client has to send a request's head")
ZARR_SHARD_BYTES = Variable("THERMCAP_ZARR_SHARD_BYTES", str(16 << 20),
                            "the most bytes a served Zarr 3 shard holds (frames are one inner chunk each)")
SAMPLES = Variable("THERMCAP_SAMPLES", None, "the sample files `thermcap bench` reads (default: ../shared/samples)")
DJI_SDK = Variable("THERMCAP_DJI_SDK", "auto", "DJI's Thermal SDK for R-JPEG imports: auto, off or its path")

VARIABLES: tuple[Variable, ...] = (ROOT, CONFIG, DATABASE_URL, TOKENS, TOKENS_FILE, CONTROL_TOKEN, S3_BUCKET,
                                   S3_ENDPOINT, S3_REGION, S3_PREFIX, CORS_ORIGINS, DASK_SCHEDULER,
                                   HEAD_TIMEOUT_S, DJI_SDK, SAMPLES, ZARR_SHARD_BYTES)


@dataclass(frozen=True)
class BucketSettings:
    """Where a bucket is: what every reader of a bucket needs, with one set of defaults."""

    bucket: str | None
    endpoint: str | None
    region: str
    prefix: str

    @classmethod
    def from_env(cls) -> BucketSettings:
        return cls(S3_BUCKET.get(), S3_ENDPOINT.get(), S3_REGION.text(), S3_PREFIX.text())
