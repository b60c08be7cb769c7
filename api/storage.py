"""The API's object store: ``archive.blobs`` configured from the service settings."""

from __future__ import annotations

from thermcap.api.settings import Settings
from thermcap.archive.blobs import BlobStore, open_store, upload_archive

__all__ = ["BlobStore", "make_store", "upload_archive"]


def make_store(settings: Settings) -> BlobStore:
    return open_store(settings.root, bucket=settings.s3_bucket, endpoint=settings.s3_endpoint,
                      region=settings.s3_region, prefix=settings.s3_prefix)
