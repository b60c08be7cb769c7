"""The API's ``thermcap`` subcommands: serve, index, upload, worker, gc, watch, jobs."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from thermcap.recorder import settings as env
from thermcap.recorder.cli.options import PORT, SIZE, Number, fail, json_option, root_option
from thermcap.recorder.exceptions import ThermcapError

__all__ = ["index", "jobs", "on_archived", "serve", "upload"]


@click.command()
@root_option
@click.option("-H", "--host", default="127.0.0.1", show_default=True,
              help="Interface to bind; 0.0.0.0 exposes the service to the network (set tokens first).")
@click.option("-p", "--port", type=PORT, default=8000, show_default=True, help="0 picks a free port.")
@click.option("--workers", type=Number(minimum=1, maximum=64, integer=True), default=1, show_default=True)
@click.option("--get", "get_path", default=None,
              help="Answer one GET request in-process, print it, exit (1 unless 200).")
@click.option("--access-log/--no-access-log", default=True, show_default=True,
              help="A line a request on stderr (uvicorn's); /metrics counts requests either way.")
def serve(root: str, host: str, port: int, workers: int, get_path: str | None, access_log: bool) -> None:
    """Serve the data root over HTTP (catalog, frames, exports, archives, browser view)."""
    import os

    from thermcap.api.app import create_app
    from thermcap.api.settings import Settings

    if not Path(root).is_dir():  # a typo would otherwise serve an empty catalog, and look fine
        fail(f"{root}: no such data root; record or import into it first, or pass the right --root")
    os.environ[env.ROOT.name] = root  # the workers build their own app from the environment
    try:
        settings = Settings(root=Path(root))
    except ValueError as exc:
        fail(str(exc))
    if get_path:
        from fastapi.testclient import TestClient

        with TestClient(create_app(settings)) as client:
            r = client.get(get_path)
        kind = r.headers.get("content-type", "")
        if kind.startswith(("text/", "application/json")):
            click.echo(r.text)
        else:  # an image or raw counts: the bytes as they are, for a pipe or a file
            click.echo(r.content, nl=False)
        sys.exit(0 if r.status_code == 200 else 1)
    from thermcap.recorder.loopback import is_loopback

    if not is_loopback(host) and not settings.tokens:
        click.secho(f"warning: serving on {host} with no tokens: anyone who can reach it can read every session",
                    fg="yellow", err=True)
    import uvicorn

    from thermcap.api.request_head import BoundedHead

    # the request head bounded in bytes and time before the app sees it (request_head.py)
    if workers > 1:
        uvicorn.run("thermcap.api.app:create_app", factory=True, host=host, port=port, workers=workers,
                    log_level="info", access_log=access_log, http=BoundedHead)
    else:
        uvicorn.run(create_app(settings), host=host, port=port, log_level="info", access_log=access_log,
                    http=BoundedHead)


@click.command("index")
@click.argument("root_arg", required=False, metavar="[ROOT]")
@root_option
@click.option("--force", is_flag=True, help="Re-index sessions even when unchanged.")
@json_option
def index(root_arg: str | None, root: str, force: bool, as_json: bool) -> None:
    """Index (or re-index) the sessions under ROOT for the API; idempotent."""
    from sqlalchemy.exc import SQLAlchemyError

    from thermcap.api.db import make_engine, migrate
    from thermcap.api.indexing import index_root
    from thermcap.api.settings import Settings
    from thermcap.api.storage import make_store

    settings = Settings(root=Path(root_arg or root))
    try:
        engine = make_engine(settings.db_url)
        migrate(engine)
        result = index_root(engine, settings.root, force=force, store=make_store(settings))
    except SQLAlchemyError as exc:
        fail(index_db_problem(settings, exc))
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
    else:
        click.echo(f"indexed {len(result.indexed)}, unchanged {len(result.unchanged)}, "
                   f"removed {len(result.removed)}, failed {len(result.failed)}")
        for name, err in result.failed.items():
            click.echo(f"  {name}: {err}", err=True)
        for name, why in result.skipped.items():
            click.echo(f"  {name}: not indexed: {why}", err=True)
        for name, problems in result.damaged.items():
            click.echo(f"  {name}: {'; '.join(problems)}", err=True)
    if result.failed:
        sys.exit(1)


def index_db_problem(settings: Any, exc: Exception) -> str:
    """One line for an index database that cannot be used, naming it (never its password)."""
    from thermcap.api.settings import _redact

    orig = getattr(exc, "orig", None) or exc
    why = str(orig).splitlines()[0] if str(orig) else type(orig).__name__
    url = settings.db_url
    if url.startswith("sqlite:///"):
        folder = Path(url[len("sqlite:///"):]).parent
        if folder.exists() and not os.access(folder, os.W_OK):
            why += f" ({folder} is read-only)"
    return f"the index database {_redact(url)} cannot be used: {why}"


@click.command()
@click.argument("sessions", nargs=-1, required=True)
@root_option
@json_option
def upload(sessions: tuple[str, ...], root: str, as_json: bool) -> None:
    """Copy verified archives to the configured S3 store (THERMCAP_S3_BUCKET, ...)."""
    from thermcap.api.settings import Settings
    from thermcap.api.storage import make_store, upload_archive
    from thermcap.recorder.storage.reader import resolve_session

    settings = Settings(root=Path(root))
    if not settings.s3_bucket:
        fail("no object store configured: set THERMCAP_S3_BUCKET (and THERMCAP_S3_ENDPOINT for SeaweedFS/MinIO)")
    store = make_store(settings)
    out = {}
    for s in sessions:
        try:
            d = resolve_session(s, root)
            out[str(d)] = upload_archive(store, settings.root, d)
        except (ThermcapError, OSError, FileNotFoundError) as exc:
            fail(f"{s}: {exc}")
    click.echo(json.dumps(out, indent=2) if as_json else "\n".join(f"{k}: {len(v)} objects" for k, v in out.items()))


def on_archived(session_dir: Path, root: Path) -> None:
    """Hook run by ``thermcap archive`` once a session verified: index it right away."""
    from thermcap.api.db import make_engine, migrate
    from thermcap.api.indexing import index_session
    from thermcap.api.settings import Settings
    from thermcap.api.storage import make_store

    settings = Settings(root=Path(root))
    engine = make_engine(settings.db_url)
    migrate(engine)
    index_session(engine, session_dir, store=make_store(settings))  # where `serve` reads the frames files


@click.command()
@root_option
@click.option("--formats", default="png16,tiff-lzw,hdf5,jxl", show_default=True)
@click.option("--once", is_flag=True, help="One pass over the root, then exit.")
@click.option("--interval", type=float, default=5.0, show_default=True, help="Seconds between passes.")
@click.option("--delete-source", is_flag=True,
              help="Delete the MCAP source once every format verified (and uploaded, with a bucket).")
@click.option("--scheduler", envvar=env.DASK_SCHEDULER.name, default=None, metavar="tcp://HOST:8786",
              help="A Dask cluster's scheduler (dask-jobqueue, dask-kubernetes or `dask scheduler`); without "
                   "it, an in-process LocalCluster runs the same tasks.")
@click.option("--local-workers", type=int, default=None, metavar="N",
              help="Task threads of the in-process LocalCluster  [default: 2, or 1 on one core]")
@click.option("--scrub-interval", type=float, default=86400.0, show_default=True,
              help="Seconds between scrubs of every archived session, as Dask tasks (0: never).")
@click.option("--analyze", is_flag=True,
              help="Also run the hot-spot analysis (a task after the archive) on sessions that have none.")
@json_option
def worker(root: str, formats: str, once: bool, interval: float, delete_source: bool, scheduler: str | None,
           local_workers: int | None, scrub_interval: float, analyze: bool, as_json: bool) -> None:
    """Archive, verify, upload (when THERMCAP_S3_BUCKET is set) and index finished sessions, as Dask
    tasks: one per segment, in parallel, then a finalize per session."""
    import time as _time

    from thermcap.api.db import make_engine, migrate
    from thermcap.api.jobs.dask_jobs import DaskJobs, TaskConfig
    from thermcap.api.jobs.worker import Worker
    from thermcap.api.settings import Settings
    from thermcap.api.storage import make_store

    settings = Settings(root=Path(root))
    engine = make_engine(settings.db_url)
    migrate(engine)
    store = make_store(settings) if settings.s3_bucket else None
    fmts = [f for f in formats.split(",") if f]
    w = Worker(settings.root, engine, formats=fmts, store=store, delete_source=delete_source,
               log=(lambda m: None) if as_json else click.echo)
    s3 = ({"bucket": settings.s3_bucket, "endpoint": settings.s3_endpoint, "region": settings.s3_region,
           "prefix": settings.s3_prefix} if settings.s3_bucket else None)
    # Without a scheduler: an in-process LocalCluster of threads (the codecs release the GIL), so
    # the same tasks run with no server to start and end with this process.
    runner = DaskJobs(w, TaskConfig(str(settings.root.resolve()), tuple(fmts), settings.db_url, s3, delete_source,
                                    analyze),
                      scheduler=scheduler, local_workers=local_workers or min(2, os.cpu_count() or 1),
                      processes=False)
    try:
        if once:
            res = runner.run_once()
            w.heartbeat()
            if as_json:
                click.echo(json.dumps(res.to_dict(), indent=2))
            sys.exit(1 if res.failed else 0)
        next_scrub = _time.monotonic() + scrub_interval if scrub_interval > 0 else None
        while True:
            runner.run_once()
            w.heartbeat()
            if next_scrub is not None and _time.monotonic() >= next_scrub:
                found = runner.scrub()
                w.log(f"scrub: {found['sessions']} sessions, {found['findings']} damaged copies found")
                next_scrub = _time.monotonic() + scrub_interval
            _time.sleep(interval)
    finally:
        runner.close()


@click.command()
@root_option
@click.option("--keep-days", type=Number(minimum=0, maximum=36_500, unit="days"), default=None,
              help="Delete sessions older than this many days (0: any age).")
@click.option("--max-bytes", type=SIZE, default=None, metavar="SIZE",
              help="Keep the root under this size (500G and 2T count in 1024s, 2TB in 1000s).")
@click.option("--require-upload/--no-require-upload", default=None,
              help="Only delete sessions already uploaded (default: on when a store is configured).")
@click.option("--dry-run", is_flag=True, help="Print what would be deleted and the bytes freed.")
@click.option("--include-protected", is_flag=True,
              help="Also delete sessions whose event windows are protected (kept by default).")
@json_option
def gc(root: str, keep_days: float | None, max_bytes: int | None, require_upload: bool | None, dry_run: bool,
       include_protected: bool, as_json: bool) -> None:
    """Retention: delete the oldest verified sessions by age and/or total size (FIFO)."""
    from thermcap.api.jobs.retention import gc_sessions
    from thermcap.api.settings import Settings

    if keep_days is None and max_bytes is None:
        fail("give --keep-days and/or --max-bytes")
    settings = Settings(root=Path(root))
    limit = max_bytes
    req = bool(settings.s3_bucket) if require_upload is None else require_upload
    from thermcap.api.storage import make_store

    store = make_store(settings) if settings.s3_bucket else None
    try:
        res = gc_sessions(settings.root, keep_days=keep_days, max_bytes=limit, require_upload=req, dry_run=dry_run,
                          store=store, include_protected=include_protected)
    except OSError as exc:
        fail(f"{exc.filename or settings.root}: {exc.strerror or exc}")
    if as_json:
        click.echo(json.dumps(res.to_dict(), indent=2))
        return
    verb = "would delete" if dry_run else "deleted"
    for d in res.decisions:
        if d.action == "keep":
            click.echo(f"keep {d.session}: {d.why_kept}")
        else:
            what = "MCAP source" if d.action == "delete-source" else "local folder"
            click.echo(f"{verb} {what} of {d.session} ({d.frees:,} bytes), relying on: {'; '.join(d.relies_on)}")
    click.echo(f"{verb} {sum(x.frees for x in res.deleted):,} bytes in {len(res.deleted)} sessions; "
               f"{res.bytes_remaining:,} bytes remain; "
               f"{sum(1 for x in res.decisions if x.action == 'keep')} kept (nothing else covers them)")


@click.command("watch")
@click.argument("inbox")
@root_option
@click.option("--once", is_flag=True, help="One pass, then exit.")
@click.option("--interval", type=float, default=5.0, show_default=True, help="Seconds between passes.")
@click.option("--settle", type=float, default=2.0, show_default=True,
              help="A file is taken once it has not changed for this many seconds.")
@click.option("--archive/--no-archive", default=True, show_default=True, help="Archive and verify each session.")
@click.option("--formats", default="png16,hdf5", show_default=True)
@click.option("--endpoint", envvar=env.S3_ENDPOINT.name, default=None,
              help="s3:// inboxes: the S3-compatible endpoint (credentials from AWS_ACCESS_KEY_ID / "
                   "AWS_SECRET_ACCESS_KEY).")
@click.option("--region", envvar=env.S3_REGION.name, default=env.S3_REGION.default, show_default=True)
@click.option("--scheduler", envvar=env.DASK_SCHEDULER.name, default=None, metavar="tcp://HOST:8786",
              help="Take the files as tasks on this Dask cluster (its workers must see INBOX and ROOT); "
                   "without it, one after another here.")
@json_option
def watch(inbox: str, root: str, once: bool, interval: float, settle: float, archive: bool, formats: str,
          endpoint: str | None, region: str, scheduler: str | None, as_json: bool) -> None:
    """Take in every camera file dropped in INBOX (a folder, or s3://BUCKET/PREFIX) exactly once: import,
    archive, derived products beside it (heatmap PNG, °C GeoTIFF, surface_temperature summary); bad files
    to quarantine/."""
    import time as _time

    from thermcap.api.jobs.inbox import InboxBusy, process_inbox

    fmts = [f.strip() for f in formats.split(",") if f.strip()] if archive else None
    log = (lambda m: None) if as_json else (lambda m: click.echo(m, err=True))
    bucket_inbox: Callable[[], Any] | None = None
    if inbox.startswith("s3://"):
        from thermcap.api.jobs.bucket_inbox import parse_bucket_url, process_bucket_inbox
        from thermcap.archive.blobs import open_store

        try:
            bucket, prefix = parse_bucket_url(inbox)
        except ThermcapError as exc:
            fail(str(exc))
        store = open_store(Path(root), bucket=bucket, endpoint=endpoint, region=region)

        def one_pass() -> Any:
            return process_bucket_inbox(store, prefix, root, bucket=bucket, archive_formats=fmts, log=log)
        bucket_inbox = one_pass
    client = None
    if scheduler and bucket_inbox is None:
        from distributed import Client

        client = Client(scheduler, timeout=30)
    while True:
        try:
            res = bucket_inbox() if bucket_inbox is not None else process_inbox(inbox, root, settle_s=settle,
                                                                    archive_formats=fmts, log=log, client=client)
        except InboxBusy as exc:
            if once:
                fail(str(exc))
            _time.sleep(interval)  # a standby: the other watcher's pass ends, or it dies and frees the lock
            continue
        except ThermcapError as exc:
            fail(str(exc))
        if as_json:
            click.echo(json.dumps(res.to_dict()))
        if once:
            sys.exit(1 if res.quarantined else 0)
        _time.sleep(interval)


@click.command("jobs")
@root_option
@click.option("--state", type=click.Choice(["queued", "running", "done", "failed"]), default=None)
@click.option("--kind", default=None, help="archive, series, ...")
@click.option("--session", "session_id", default=None)
@click.option("--limit", type=int, default=50, show_default=True)
@json_option
def jobs(root: str, state: str | None, kind: str | None, session_id: str | None, limit: int, as_json: bool) -> None:
    """Jobs from the index (THERMCAP_DATABASE_URL, or ROOT's SQLite): the API's series and the
    workers' archive tasks, with attempts, the worker that ran them and why one failed."""
    from sqlalchemy.exc import SQLAlchemyError

    from thermcap.api.db import make_engine, migrate
    from thermcap.api.jobs.records import list_jobs
    from thermcap.api.settings import Settings

    settings = Settings(root=Path(root))
    try:
        engine = make_engine(settings.db_url)
        migrate(engine)
        found = list_jobs(engine, state=state, kind=kind, session_id=session_id, limit=limit)
    except SQLAlchemyError as exc:
        fail(index_db_problem(settings, exc))
    if as_json:
        click.echo(json.dumps([j.to_dict(with_result=False) for j in found], indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table("job", "kind", "session", "state", "tries", "worker", "seconds", "error")
    for j in found:
        table.add_row(j.id, j.kind, j.session_id or "", j.state, str(j.attempts), j.worker or "",
                      f"{j.seconds:.1f}" if j.seconds is not None else "", (j.error or "")[:80])
    Console().print(table if found else "no jobs")
