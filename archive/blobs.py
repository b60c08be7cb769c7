"""Archive blobs through obstore: the local data root by default, any S3-compatible store when
configured. Keys are paths relative to the data root (``sessions/<id>/archive/<fmt>/<file>``),
the same on disk and in the bucket, so one code path serves both. Uploading (create-only) and
scrub's re-reads of the bucket copies live here, beside the store they use."""

from __future__ import annotations

import io
import os
from collections.abc import AsyncIterator, Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import obstore
from obstore.store import LocalStore, S3Store

from thermcap.recorder.install_hint import install_command
from thermcap.recorder.storage.layout import EVENTS_JSON, RADIOMETRY_JSON, SESSION_JSON, SessionLayout

__all__ = ["BlobFile", "BlobStore", "open_store", "session_documents", "stored_digest", "upload_archive"]


class BlobStore:
    def __init__(self, store: Any, *, prefix: str = "", kind: str = "local", url: str | None = None) -> None:
        self.store = store
        self.prefix = prefix.strip("/")
        self.kind = kind
        self.url = url  # s3://BUCKET, where others read its objects from (reference files name it)

    def _key(self, key: str) -> str:
        return f"{self.prefix}/{key}" if self.prefix else key

    def head(self, key: str) -> dict[str, Any] | None:
        try:
            return dict(obstore.head(self.store, self._key(key)))
        except FileNotFoundError:
            return None

    def get_range(self, key: str, start: int, end: int) -> bytes:
        """Bytes [start, end) of a blob."""
        return bytes(obstore.get_range(self.store, self._key(key), start=start, end=end))

    async def stream_range(self, key: str, start: int, end: int, chunk: int = 1 << 20) -> AsyncIterator[bytes]:
        """[start, end) in pieces, so a multi-GB download never sits in memory."""
        pos = start
        while pos < end:
            stop = min(end, pos + chunk)
            data = await obstore.get_range_async(self.store, self._key(key), start=pos, end=stop)
            yield bytes(data)
            pos = stop

    def iter_bytes(self, key: str, chunk: int = 8 << 20) -> Iterator[bytes]:
        """A whole blob in pieces (scrub hashes bucket copies without holding them)."""
        head = self.head(key)
        if head is None:
            raise FileNotFoundError(key)
        pos, size = 0, head["size"]
        while pos < size:
            stop = min(size, pos + chunk)
            yield self.get_range(key, pos, stop)
            pos = stop

    def list(self, prefix: str) -> Iterator[tuple[str, int]]:
        """(key, size) of every blob under ``prefix``, keys without the store's own prefix."""
        cut = len(self.prefix) + 1 if self.prefix else 0
        for batch in obstore.list(self.store, self._key(prefix)):
            for meta in batch:
                yield str(meta["path"])[cut:], int(meta["size"])

    def delete(self, key: str) -> None:
        obstore.delete(self.store, self._key(key))

    def put_bytes(self, key: str, data: bytes) -> None:
        obstore.put(self.store, self._key(key), data, mode="overwrite")

    def put_file(self, key: str, path: Path, *, overwrite: bool = True) -> None:
        with open(path, "rb") as f:
            obstore.put(self.store, self._key(key), f, mode="overwrite" if overwrite else "create")

    def sign(self, key: str, expires_s: int = 300) -> str | None:
        if self.kind != "s3":
            return None
        from datetime import timedelta

        return obstore.sign(self.store, "GET", self._key(key), timedelta(seconds=expires_s))


def stored_digest(store: BlobStore, key: str, name: str) -> str | None:
    """The ``name`` digest of an object as the store gives it back now; None when it is not there."""
    from thermcap.recorder.storage.digest import new_hasher

    h = new_hasher(name)
    try:
        for piece in store.iter_bytes(key):
            h.update(piece)
    except FileNotFoundError:
        return None
    return h.hexdigest()


def open_store(root: Path, *, bucket: str | None = None, endpoint: str | None = None, region: str = "us-east-1",
               prefix: str = "") -> BlobStore:
    """The local root, or an S3-compatible bucket (credentials from AWS_ACCESS_KEY_ID /
    AWS_SECRET_ACCESS_KEY, never passed around or logged)."""
    if bucket:
        kwargs: dict[str, Any] = {"region": region}
        if endpoint:
            kwargs["endpoint"] = endpoint
            kwargs["virtual_hosted_style_request"] = False
            if endpoint.startswith("http://"):
                kwargs["client_options"] = {"allow_http": True}
        for env, key in (("AWS_ACCESS_KEY_ID", "access_key_id"), ("AWS_SECRET_ACCESS_KEY", "secret_access_key")):
            if os.environ.get(env):
                kwargs[key] = os.environ[env]
        # a read the store keeps failing (a rotted object fails its own CRC) is said in seconds,
        # not after object_store's ten retries (147 s, seen): the caller tries another copy
        kwargs["retry_config"] = {"max_retries": 3, "retry_timeout": timedelta(seconds=20),
                                  "backoff": {"init_backoff": timedelta(milliseconds=100),
                                              "max_backoff": timedelta(seconds=2), "base": 2}}
        return BlobStore(S3Store(bucket, **kwargs), prefix=prefix, kind="s3", url=f"s3://{bucket}")
    root.mkdir(parents=True, exist_ok=True)
    return BlobStore(LocalStore(str(root.resolve())), kind="local")


def upload_archive(store: BlobStore, root: Path, session_dir: Path) -> list[str]:
    """Upload a session's verified archive files with create-only writes, then its manifest.

    An object already there with the same size is taken as uploaded (a rerun after a crash); one
    with another size is an error, never an overwrite. The manifest records the upload, so
    ``--delete-source`` and ``gc`` know the data is safe elsewhere. Returns the keys.
    """
    from obstore.exceptions import AlreadyExistsError

    from thermcap.archive.manifest import archived_files, digest_problem, iso_now, load_manifest, save_manifest
    from thermcap.recorder.exceptions import ThermcapError

    manifest = load_manifest(session_dir)
    keys = []
    etags: dict[str, str] = {}
    for rec in archived_files(manifest):
        path = SessionLayout.of(session_dir).archive / rec.rel
        key = path.resolve().relative_to(root.resolve()).as_posix()
        # what gc later lets the bucket stand for must be the verified bytes: the local file is
        # hashed before it goes, and the object read back and hashed after
        if digest_problem(path, rec.named) is not None:
            raise ThermcapError(f"{path}: missing or differs from the manifest; not uploading a damaged copy "
                                f"(`thermcap scrub --repair` rebuilds it)")
        head = store.head(key)
        if head is None:
            try:
                with open(path, "rb") as f:
                    obstore.put(store.store, store._key(key), f, mode="create")
            except AlreadyExistsError:
                pass
            head = store.head(key)
        if head is None or head["size"] != rec.bytes:
            raise ThermcapError(f"{key} already exists in the store with different content "
                                f"({head['size'] if head else 'no'} bytes, expected {rec.bytes}); "
                                f"refusing to overwrite")
        if stored_digest(store, key, rec.digest) != rec.hex:
            raise ThermcapError(f"{key}: the store holds other bytes than the verified archive file; "
                                f"refusing to overwrite (delete the object, then upload again)")
        keys.append(key)
        if head.get("e_tag"):
            etags[key] = str(head["e_tag"])
    references = _upload_references(store, root, session_dir, [k for k in keys if k.endswith(".h5")])
    documents = _upload_documents(store, root, session_dir)
    manifest["upload"] = {"complete": True, "keys": keys, "etags": etags, "at": iso_now(), "store": store.kind,
                          "references": references, "documents": documents}
    save_manifest(session_dir, manifest)
    manifest_path = SessionLayout.of(session_dir).manifest
    store.put_file(manifest_path.resolve().relative_to(root.resolve()).as_posix(), manifest_path)
    return keys


#: The session's own small documents, sent beside the archive so a reader of the bucket alone
#: (``thermcap.open("s3://...")``) has its metadata, events and model versions. They change (a
#: new ``thermcap radiometry`` version), so each upload overwrites them; the archive files never.
SESSION_DOCUMENTS = (SESSION_JSON, EVENTS_JSON, RADIOMETRY_JSON)


def session_documents(root: Path, session_dir: Path) -> list[tuple[Path, str]]:
    """(file, object key) of each of the session's documents on disk: what `upload` sends and
    `gc` compares before the folder goes."""
    return [(session_dir / name, (session_dir / name).resolve().relative_to(root.resolve()).as_posix())
            for name in SESSION_DOCUMENTS if (session_dir / name).is_file()]


def _upload_documents(store: BlobStore, root: Path, session_dir: Path) -> list[str]:
    if store.kind != "s3":
        return []  # a local store is the root itself: they are already there
    sent = []
    for path, key in session_documents(root, session_dir):
        store.put_file(key, path)
        sent.append(key)
    return sent


def _upload_references(store: BlobStore, root: Path, session_dir: Path, h5_keys: list[str]) -> dict[str, Any]:
    """A kerchunk reference file beside each HDF5 archive in a bucket (``archive.hdf5_refs``), so
    xarray reads its chunks straight from S3; what could not be written is said, never fatal:
    the archive itself is uploaded and verified."""
    if store.kind != "s3" or not h5_keys or store.url is None:
        return {}
    try:
        from thermcap.archive.hdf5_refs import REFS_SUFFIX, hdf5_references
    except ImportError as exc:
        return {"skipped": f"kerchunk is not installed ({exc.name}); {install_command('python')}"}
    import json
    import tempfile

    written: dict[str, Any] = {}
    for key in h5_keys:
        path = root / key
        try:
            refs = hdf5_references(path, f"{store.url}/{store._key(key)}")
        except Exception as exc:  # the archive stands without its references
            written[key] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as tmp:
            json.dump(refs, tmp)
        try:
            store.put_file(key + REFS_SUFFIX, Path(tmp.name))
        finally:
            Path(tmp.name).unlink(missing_ok=True)
        written[key] = {"references": key + REFS_SUFFIX}
    return written


class BlobFile(io.RawIOBase):
    """A stored blob as a seekable file (ranged reads), so mcap's seeking reader can fetch one
    attachment from ``extras.mcap`` on S3 without downloading the whole file."""

    def __init__(self, store: BlobStore, key: str, size: int) -> None:
        self.store, self.key, self.size, self.pos = store, key, size, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        self.pos = {io.SEEK_SET: 0, io.SEEK_CUR: self.pos, io.SEEK_END: self.size}[whence] + offset
        return self.pos

    def tell(self) -> int:
        return self.pos

    def readinto(self, buffer: Any) -> int:
        end = min(self.size, self.pos + len(buffer))
        if end <= self.pos:
            return 0
        data = self.store.get_range(self.key, self.pos, end)
        buffer[:len(data)] = data
        self.pos += len(data)
        return len(data)
