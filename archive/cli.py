"""The archive's ``thermcap`` subcommands: archive, verify, audit, and ``bench archive``."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import click

from thermcap.archive.defaults import DEFAULT_FORMATS
from thermcap.recorder import settings
from thermcap.recorder.cli.options import Number, fail, json_option, root_option
from thermcap.recorder.exceptions import SessionBusyError, ThermcapError
from thermcap.recorder.storage.digest import DEFAULT_DIGEST, DIGESTS
from thermcap.recorder.storage.layout import SessionLayout

__all__ = ["archive", "audit", "scrub", "verify"]


def _formats(value: str) -> list[str]:
    from thermcap.archive.formats import format_registry

    out = [v.strip() for v in value.split(",") if v.strip()]
    unknown = [v for v in out if v not in format_registry]
    if unknown:
        raise click.BadParameter(f"unknown format(s) {', '.join(unknown)}; known: {', '.join(sorted(format_registry))}")
    return out


@click.command()
@click.argument("sessions", nargs=-1)
@root_option
@click.option("--all", "all_sessions", is_flag=True, help="Every finished session under ROOT not yet archived.")
@click.option("--formats", default=",".join(DEFAULT_FORMATS), show_default=True,
              help="Comma-separated: png16, tiff-lzw, hdf5, jxl, htj2k, jpegls.")
@click.option("--delete-source", is_flag=True, help="Delete the MCAP segments once every format verified.")
@click.option("--force", is_flag=True, help="Rewrite formats that are already archived.")
@click.option("--workers", type=Number(minimum=1, maximum=64, integer=True), default=None,
              help="Encoder threads in all: shared among the formats written at once, which take turns "
                   "when there are more of them (default: the usable cores).")
@click.option("--digest", type=click.Choice(list(DIGESTS)), default=DEFAULT_DIGEST, show_default=True,
              help="The hash of the manifest's proofs (every frame, every file). sha256 where a rule asks for "
                   "it (FIPS 180-4, a repository's ingest); blake3 is as strong and 5x faster.")
@json_option
def archive(sessions: tuple[str, ...], root: str, all_sessions: bool, formats: str, delete_source: bool, force: bool,
            workers: int | None, digest: str, as_json: bool) -> None:
    """Repack sessions losslessly, verify every frame bit-exact, write archive/manifest.json."""
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn

    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.cli.progress import progress
    from thermcap.recorder.storage.reader import list_sessions, read_session_meta, resolve_session

    try:
        fmts = _formats(formats)
        dirs = [resolve_session(s, root) for s in sessions]
        if all_sessions:
            # a session of several cameras already split is archived through its per-camera sessions
            dirs += [d for d in list_sessions(root) if not SessionLayout.of(d).manifest.exists()
                     and not list(d.glob("*.active")) and not read_session_meta(d).get("split_into")]
    except (ThermcapError, click.BadParameter) as exc:
        fail(str(exc))
    if not dirs:
        fail("no session given (pass SESSION paths or ids, or --all)")
    results: list[dict[str, Any]] = []
    failed = False
    with progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                  as_json=as_json) as bar:
        for k, d in enumerate(dirs, 1):
            task = bar.add_task(d.name, total=None)
            label = f"{d.name} ({k}/{len(dirs)})"

            def on_progress(what: str, done: int, total: int, task=task, name=label) -> None:
                bar.update(task, description=f"{name}: {what}", completed=done, total=total)

            try:
                # the index learns of the archive before the source goes: no frame 503s in between
                m = archive_session(d, fmts, delete_source=delete_source, force=force, workers=workers,
                                    on_progress=on_progress, before_delete=lambda sd: _run_hooks(sd, root),
                                    digest=digest)
                results.append({"session": str(d), "ok": True, "formats": {
                    k: {x: v[x] for x in ("verified", "bytes", "objects", "compression_ratio", "encode_fps",
                                          "decode_fps")} for k, v in m["formats"].items() if k in fmts},
                    "source_deleted": m["source"].get("deleted", False),
                    "source_kept_because": m["source"].get("kept_because")})
                _run_hooks(d, root)
            except ThermcapError as exc:
                failed = True
                results.append({"session": str(d), "ok": False, "error": str(exc)})
            bar.remove_task(task)
            if not as_json:  # each session as it ends, not all at the end of a long run
                _print_archived(results[-1])
    if as_json:
        click.echo(json.dumps(results, indent=2))
    if failed:
        sys.exit(1)


def _print_archived(r: dict[str, Any]) -> None:
    if not r["ok"]:
        click.echo(f"error: {r['error']}", err=True)
        return
    kept = f" (MCAP source kept: {r['source_kept_because']})" if r["source_kept_because"] else ""
    click.echo(f"{r['session']}: archived" + (" (MCAP source deleted)" if r["source_deleted"] else kept))
    for fid, f in r["formats"].items():
        click.echo(f"  {fid:9} {'verified' if f['verified'] else 'FAILED':8} {f['bytes']:>14,} bytes  "
                   f"{f['objects']:>3} objects  ratio {f['compression_ratio']}  "
                   f"encode {f['encode_fps']} fps  decode {f['decode_fps']} fps")


def _run_hooks(session_dir: Path, root: str) -> None:
    """Tell interested packages (the API's index, registered by the facade) that a session's
    archive verified."""
    from thermcap.archive.hooks import ON_ARCHIVED

    for name, hook in ON_ARCHIVED:
        try:
            hook(session_dir, Path(root))
        except Exception as exc:  # indexing can be redone with `thermcap index`; the archive stands
            click.echo(f"warning: {name} hook failed for {session_dir}: {exc}", err=True)


@click.command()
@click.argument("sessions", nargs=-1, required=True)
@root_option
@click.option("--formats", default=None, help="Only these formats (default: all in the manifest).")
@json_option
def verify(sessions: tuple[str, ...], root: str, formats: str | None, as_json: bool) -> None:
    """Re-check archives against the manifest's frame hashes (works after the MCAP is deleted)."""
    from thermcap.archive.verify import CopyCheck, verify_session
    from thermcap.recorder.storage.reader import resolve_session

    out: dict[str, dict[str, CopyCheck]] = {}
    bad = False
    for s in sessions:
        try:
            d = resolve_session(s, root)
            report = verify_session(d, _formats(formats) if formats else None)
        except (ThermcapError, click.BadParameter) as exc:
            fail(str(exc))
        out[str(d)] = report
        bad |= any(not r.ok for r in report.values())
    if as_json:
        click.echo(json.dumps({name: {fid: r.to_dict() for fid, r in rep.items()} for name, rep in out.items()},
                              indent=2))
    else:
        for name, report in out.items():
            for fid, r in report.items():
                what = ("attachments, metadata and other topics intact" if fid == "extras"
                        else f"{r.frames} frames bit-exact")
                click.echo(f"{name} {fid}: {'ok, ' + what if r.ok else 'FAILED'}")
                for p in r.problems:
                    click.echo(f"  {p}")
    if bad:
        sys.exit(1)


@click.command()
@click.argument("root_arg", metavar="[ROOT]", required=False, type=click.Path(file_okay=False))
@root_option
@click.option("--session", "sessions", multiple=True, help="Only this session (id or path); repeatable.")
@click.option("--repair", is_flag=True, help="Rebuild each damaged copy from another verified one, then verify it.")
@click.option("--workers", type=Number(minimum=1, maximum=64, integer=True), default=2, show_default=True,
              help="Encoder threads for repairs.")
@json_option
def scrub(root_arg: str | None, root: str, sessions: tuple[str, ...], repair: bool, workers: int,
          as_json: bool) -> None:
    """Re-verify every archive copy (formats, extras.mcap, object-store objects) and mark damage.

    Damaged copies are marked in the manifest, so the API stops offering them and gc no longer
    counts them; --repair rebuilds them from a verified copy. Exit 1 if damage remains."""

    from thermcap.archive.blobs import open_store
    from thermcap.archive.scrub import ScrubReport, scrub_session
    from thermcap.recorder.cli.progress import progress
    from thermcap.recorder.storage.reader import list_sessions, resolve_session

    base = Path(root_arg or root)
    where = settings.BucketSettings.from_env()
    store = open_store(base, bucket=where.bucket, endpoint=where.endpoint, region=where.region,
                       prefix=where.prefix) if where.bucket else None
    try:
        dirs = [resolve_session(s, base) for s in sessions] if sessions else \
            [d for d in list_sessions(base) if SessionLayout.of(d).manifest.is_file()]
    except ThermcapError as exc:
        fail(str(exc))
    report = ScrubReport()
    with progress(as_json=as_json) as bar:
        task = bar.add_task("scrubbing", total=len(dirs))
        for d in dirs:
            before = len(report.findings)
            try:
                scrub_session(d, repair=repair, store=store, root=base, workers=workers, report=report)
            except ThermcapError as exc:
                fail(str(exc))
            if len(report.findings) > before:
                _run_hooks(d, str(base))  # the index drops (or takes back) the copies at once
            bar.advance(task)
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2))
    else:
        for f in report.findings:
            state = (f"repaired from {f.repaired_from}" if f.repaired else
                     f"NOT repaired ({f.repair_error})" if repair else "marked damaged")
            click.echo(f"{f.session}: {f.copy}: {f.problems[0]}{' ...' if len(f.problems) > 1 else ''} -> {state}")
        for s, who in report.skipped.items():
            click.echo(f"{s}: skipped, {who} is working on it")
        click.echo(f"scrubbed {report.sessions} sessions, {report.copies_checked} copies: {report.damaged} damaged, "
                   f"{report.repaired} repaired")
    if not report.ok:
        sys.exit(1)


@click.command()
@click.argument("sessions", nargs=-1)
@root_option
@click.option("--prices", type=click.Path(dir_okay=False), default=None,
              help="JSON price table overriding the defaults.")
@click.option("--project-cameras", type=Number(minimum=1, maximum=1_000_000, integer=True), default=None,
              help="Projection: number of cameras.")
@click.option("--project-hours", type=Number(minimum=0, above=True, maximum=24, unit="h"), default=8.0,
              show_default=True,
              help="Projection: recorded hours a day per camera.")
@click.option("--project-days", type=Number(minimum=1, maximum=36500, integer=True), default=365, show_default=True)
@click.option("--project-segment-s", type=Number(minimum=0, above=True, unit="s"), default=60.0, show_default=True,
              help="Projection: segment length (one object per segment; hdf5: one per camera-day).")
@click.option("--project-retention-days", type=Number(minimum=1, maximum=36500, integer=True), default=None,
              help="Projection: each day's data is deleted after this many days (default: kept for the whole "
                   "period).")
@click.option("--markdown", is_flag=True, help="Print a Markdown table instead of the aligned one.")
@json_option
def audit(sessions: tuple[str, ...], root: str, prices: str | None, project_cameras: int | None,
          project_hours: float, project_days: int, project_segment_s: float, project_retention_days: int | None,
          markdown: bool, as_json: bool) -> None:
    """Storage cost of archived sessions per sensor and kind (continuous or stills), per format and
    tier, with the format to keep for each and why, what was left out, and a fleet projection."""
    from thermcap.archive.costs import audit_sessions, load_prices, project, render_markdown, render_plain
    from thermcap.recorder.storage.reader import list_sessions, resolve_session

    try:
        table = load_prices(prices)
        candidates = [resolve_session(s, root) for s in sessions] or list_sessions(root)
        dirs = [d for d in candidates if SessionLayout.of(d).manifest.exists()]
        left = [{"session": d.name, "why": "not archived yet (`thermcap archive " + d.name + "`); its MCAP "
                 f"source holds {sum(p.stat().st_size for p in SessionLayout.of(d).segments()):,} bytes"}
                for d in candidates if d not in dirs]
        if not dirs:
            fail(f"no archived sessions under {root} (run `thermcap archive` first)"
                 + (f"; {len(left)} sessions are not archived yet" if left else ""))
        report = audit_sessions(dirs, table, left)
    except ThermcapError as exc:
        fail(str(exc))
    if project_cameras:
        report["projection"] = {}
        for g in report["groups"]:
            if g["kind"] != "continuous" or not g["hours"]:
                continue
            bph = {k: v["bytes"] / g["hours"] for k, v in g["formats"].items() if v["covers_every_session"]}
            # Objects follow the segmenting, not a short sample session's object count.
            oph = {k: (1 / project_hours if k == "hdf5" else 3600 / project_segment_s) for k in bph}
            report["projection"][g["sensor"]] = project(bph, oph, cameras=project_cameras,
                                                        hours_per_day=project_hours, days=project_days,
                                                        prices=table, retention_days=project_retention_days)
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    click.echo(render_markdown(report) if markdown else render_plain(report))
    for sensor, p in (report.get("projection") or {}).items():
        click.echo(f"\nProjection for {sensor}: {p['assumes']}")
        tier = table["s3-standard"]["label"] if "s3-standard" in table else next(iter(table))
        key = "s3-standard" if "s3-standard" in table else next(iter(table))
        click.echo(f"  {'format':9} {'TiB stored at end':>18} {tier + ' $/month at end':>28} "
                   f"{tier + ' $ paid over the period':>34}")
        for fid, f in sorted(p["formats"].items(), key=lambda kv: kv[1]["stored_bytes_at_end"]):
            c = f["cost"][key]
            click.echo(f"  {fid:9} {f['tib_at_end']:>18,.3f} {c['monthly_at_end']:>28,.2f} "
                       f"{c['storage_total'] + c['put_total']:>34,.2f}")


@click.command("sync-confirm")
@click.option("--bucket", envvar=settings.S3_BUCKET.name, default=None, help="The bucket vehicles sync to.")
@click.option("--endpoint", envvar=settings.S3_ENDPOINT.name, default=None, help="S3-compatible endpoint.")
@click.option("--region", envvar=settings.S3_REGION.name, default=settings.S3_REGION.default, show_default=True)
@click.option("--prefix", envvar=settings.S3_PREFIX.name, default=settings.S3_PREFIX.default,
              help="Key prefix in the bucket.")
@click.option("--from", "from_dir", type=click.Path(file_okay=False, exists=True), default=None,
              help="Instead of a bucket: the folder vehicles sync to (`thermcap sync --to`).")
@click.option("--into", "into", type=click.Path(file_okay=False), default=None, metavar="ROOT",
              help="Then land every session that has arrived whole and receipted in ROOT/sessions, where "
                   "`thermcap worker` archives it.")
@json_option
def sync_confirm(bucket: str | None, endpoint: str | None, region: str, prefix: str, from_dir: str | None,
                 into: str | None, as_json: bool) -> None:
    """Re-read every segment vehicles shipped, re-hash every frame, and write the receipts they free space by."""
    from thermcap.archive.blobs import open_store
    from thermcap.archive.landing import land_synced
    from thermcap.archive.receipts import confirm_synced

    if bool(bucket) == bool(from_dir):
        fail("give one source: --bucket (with --endpoint) or --from DIR")
    store = open_store(Path(from_dir or "."), bucket=bucket, endpoint=endpoint, region=region, prefix=prefix)
    report = confirm_synced(store)
    try:
        landed = land_synced(store, Path(into)) if into else None
    except SessionBusyError as exc:  # the receipts above are written; only the landing waits
        fail(str(exc))
    if as_json:
        click.echo(json.dumps({**report.__dict__, **({"landing": landed.__dict__} if landed else {})}, indent=2))
    else:
        click.echo(f"{len(report.receipted)} segments receipted, {len(report.damaged)} damaged, "
                   f"{report.already} receipted before")
        for key, problem in report.damaged.items():
            click.echo(f"damaged: {key}: {problem}", err=True)
        if landed:
            click.echo(f"landed {len(landed.landed)} sessions in {into}; {len(landed.waiting)} still arriving")
            for sid, why in landed.waiting.items():
                click.echo(f"  waiting: {sid}: {why}")
            for sid, why in landed.damaged.items():
                click.echo(f"damaged: {sid}: {why}", err=True)
    if report.damaged or (landed and landed.damaged):
        sys.exit(1)

