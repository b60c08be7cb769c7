"""Where a vehicle's data goes: an S3-compatible bucket, or a directory (a depot share).

Both take an object in parts and keep what a resumed upload needs: S3's own multipart upload
(its upload id survives the vehicle; ``ListParts`` says which parts the store holds, so nothing
it holds is sent again), every part with its ``Content-MD5`` so the store refuses a part damaged
on the way, and the whole file's sha256 as the object's metadata for the cloud's check. A
directory target appends parts to ``KEY.partial`` at the offsets the journal gives, fsyncs each,
and renames the file once its sha256 matches. Receipts are read from ``receipts/KEY.json``.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import json
import os
from pathlib import Path
from typing import Any, Protocol

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.install_hint import install_command
from thermcap.recorder.storage.digest import file_sha256

__all__ = ["RECEIPTS_PREFIX", "DirTarget", "S3Target", "Target", "receipt_key"]

RECEIPTS_PREFIX = "receipts"


def receipt_key(key: str) -> str:
    return f"{RECEIPTS_PREFIX}/{key}.json"


class Target(Protocol):
    name: str

    def complete_copy(self, key: str, size: int, sha256: str) -> bool:
        """True if the store already holds exactly these bytes at ``key``."""

    def begin(self, key: str, size: int, sha256: str) -> str: ...

    def parts_held(self, key: str, upload_id: str, claimed: list[tuple[int, int, str]]) -> set[int] | None:
        """Which of the journal's ``claimed`` parts (number, size, etag) the store holds exactly;
        None if it has no such upload (expired, aborted): start again."""

    def put_part(self, key: str, upload_id: str, number: int, offset: int, body: Any, size: int,
                 md5_b64: str) -> str: ...

    def complete(self, key: str, upload_id: str, parts: list[tuple[int, str]], sha256: str) -> None: ...

    def abort(self, key: str, upload_id: str) -> None:
        """Give up an upload whose source is gone (evicted before it was sent): what the store
        holds of it goes, best effort (a store that cannot be reached now expires it itself)."""

    def put_small(self, key: str, data: bytes, sha256: str) -> None: ...

    def get_json(self, key: str) -> dict[str, Any] | None: ...


class S3Target:
    def __init__(self, bucket: str, *, endpoint: str | None = None, region: str = "us-east-1", prefix: str = "",
                 timeout_s: float = 30.0) -> None:
        try:
            import boto3
            from botocore.config import Config
        except ImportError as exc:  # pragma: no cover - the sync extra
            raise ThermcapError(f"sync to a bucket needs boto3 ({install_command('sync')})") from exc
        self.bucket, self.prefix = bucket, prefix.strip("/")
        self.name = f"s3://{bucket}/{self.prefix}" if self.prefix else f"s3://{bucket}"
        # credentials from AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY (boto3's own chain), never logged;
        # no retries of its own: the engine retries a part with backoff and journals it. The payload
        # is not hashed into the signature (the store checks every part's Content-MD5 instead), or
        # botocore would read each part twice, once to hash it and once to send it, and the cap
        # would be kept on the hashing as well as on the wire.
        self.s3 = boto3.client("s3", endpoint_url=endpoint, region_name=region,
                               config=Config(retries={"total_max_attempts": 1, "mode": "standard"},
                                             connect_timeout=timeout_s,
                                             read_timeout=timeout_s,
                                             s3={"addressing_style": "path", "payload_signing_enabled": False},
                                             request_checksum_calculation="when_required",
                                             response_checksum_validation="when_required"))

    def _k(self, key: str) -> str:
        return f"{self.prefix}/{key}" if self.prefix else key

    def _head(self, key: str) -> dict[str, Any] | None:
        from botocore.exceptions import ClientError

        try:
            return self.s3.head_object(Bucket=self.bucket, Key=self._k(key))
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("404", "NoSuchKey", "NotFound"):
                return None
            raise

    def complete_copy(self, key: str, size: int, sha256: str) -> bool:
        head = self._head(key)
        return head is not None and head["ContentLength"] == size and head.get("Metadata", {}).get("sha256") == sha256

    def begin(self, key: str, size: int, sha256: str) -> str:
        r = self.s3.create_multipart_upload(Bucket=self.bucket, Key=self._k(key), Metadata={"sha256": sha256})
        return str(r["UploadId"])

    def parts_held(self, key: str, upload_id: str, claimed: list[tuple[int, int, str]]) -> set[int] | None:
        from botocore.exceptions import ClientError

        held: dict[int, tuple[int, str]] = {}
        marker = 0
        try:
            while True:
                r = self.s3.list_parts(Bucket=self.bucket, Key=self._k(key), UploadId=upload_id,
                                       PartNumberMarker=marker)
                for p in r.get("Parts", []):
                    held[int(p["PartNumber"])] = (int(p["Size"]), str(p["ETag"]))
                if not r.get("IsTruncated"):
                    return {n for n, size, etag in claimed if held.get(n) == (size, etag)}
                marker = int(r["NextPartNumberMarker"])
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("NoSuchUpload", "404"):
                return None
            raise

    def put_part(self, key: str, upload_id: str, number: int, offset: int, body: Any, size: int, md5_b64: str) -> str:
        r = self.s3.upload_part(Bucket=self.bucket, Key=self._k(key), UploadId=upload_id, PartNumber=number,
                                Body=body, ContentLength=size, ContentMD5=md5_b64)
        return str(r["ETag"])

    def complete(self, key: str, upload_id: str, parts: list[tuple[int, str]], sha256: str) -> None:
        self.s3.complete_multipart_upload(Bucket=self.bucket, Key=self._k(key), UploadId=upload_id,
                                          MultipartUpload={"Parts": [{"PartNumber": n, "ETag": e} for n, e in parts]})

    def abort(self, key: str, upload_id: str) -> None:
        with contextlib.suppress(Exception):  # best effort: an S3 store's lifecycle rule expires the rest
            self.s3.abort_multipart_upload(Bucket=self.bucket, Key=self._k(key), UploadId=upload_id)

    def put_small(self, key: str, data: bytes, sha256: str) -> None:
        md5 = base64.b64encode(hashlib.md5(data).digest()).decode()
        self.s3.put_object(Bucket=self.bucket, Key=self._k(key), Body=data, ContentMD5=md5,
                           Metadata={"sha256": sha256})

    def get_json(self, key: str) -> dict[str, Any] | None:
        from botocore.exceptions import ClientError

        try:
            body = self.s3.get_object(Bucket=self.bucket, Key=self._k(key))["Body"].read()
        except ClientError as exc:
            if exc.response.get("Error", {}).get("Code") in ("404", "NoSuchKey", "NotFound"):
                return None
            raise
        try:
            out = json.loads(body)
        except ValueError:
            return None
        return out if isinstance(out, dict) else None


class DirTarget:
    def __init__(self, dest: Path) -> None:
        self.dest = dest
        self.name = str(dest)

    def _p(self, key: str) -> Path:
        p = (self.dest / key).resolve()
        if not p.is_relative_to(self.dest.resolve()):
            raise ThermcapError(f"{key}: outside {self.dest}")
        return p

    def complete_copy(self, key: str, size: int, sha256: str) -> bool:
        p = self._p(key)
        return p.is_file() and p.stat().st_size == size and file_sha256(p) == sha256

    def begin(self, key: str, size: int, sha256: str) -> str:
        p = self._p(key)
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p.with_name(p.name + ".partial"), "wb"):
            pass
        return "dir"

    def parts_held(self, key: str, upload_id: str, claimed: list[tuple[int, int, str]]) -> set[int] | None:
        """The claimed parts, in order, whose bytes in ``KEY.partial`` still have their MD5."""
        partial = self._p(key).with_name(self._p(key).name + ".partial")
        if not partial.is_file():
            return None
        held: set[int] = set()
        with open(partial, "rb") as f:
            for n, size, etag in sorted(claimed):
                data = f.read(size)
                if len(data) != size or hashlib.md5(data).hexdigest() != etag:
                    break
                held.add(n)
        return held

    def put_part(self, key: str, upload_id: str, number: int, offset: int, body: Any, size: int, md5_b64: str) -> str:
        partial = self._p(key).with_name(self._p(key).name + ".partial")
        h = hashlib.md5()
        with open(partial, "r+b") as f:
            f.seek(offset)
            f.truncate()
            while block := body.read(1 << 16):
                f.write(block)
                h.update(block)
            f.flush()
            os.fsync(f.fileno())
        if base64.b64encode(h.digest()).decode() != md5_b64:
            raise ThermcapError(f"{key}: part {number} arrived damaged (MD5 differs)")
        return h.hexdigest()

    def complete(self, key: str, upload_id: str, parts: list[tuple[int, str]], sha256: str) -> None:
        p = self._p(key)
        partial = p.with_name(p.name + ".partial")
        if file_sha256(partial) != sha256:
            raise ThermcapError(f"{key}: the assembled copy's sha256 differs from the vehicle's")
        os.replace(partial, p)

    def abort(self, key: str, upload_id: str) -> None:
        p = self._p(key)
        p.with_name(p.name + ".partial").unlink(missing_ok=True)

    def put_small(self, key: str, data: bytes, sha256: str) -> None:
        p = self._p(key)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_name(p.name + ".partial")
        tmp.write_bytes(data)
        os.replace(tmp, p)

    def get_json(self, key: str) -> dict[str, Any] | None:
        try:
            out = json.loads(self._p(key).read_text())
        except (OSError, ValueError):
            return None
        return out if isinstance(out, dict) else None
