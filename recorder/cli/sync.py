"""``thermcap sync``: ship a vehicle's sessions to a bucket or a depot folder, resumably."""

from __future__ import annotations

import json
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import click

from thermcap.recorder import settings
from thermcap.recorder.cli.options import Number, fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError

if TYPE_CHECKING:
    from thermcap.recorder.sync.targets import Target


def _target(bucket: str | None, endpoint: str | None, region: str, prefix: str, to: str | None) -> Target:
    from thermcap.recorder.sync.targets import DirTarget, S3Target

    if bool(bucket) == bool(to):
        raise ThermcapError("give one destination: --bucket (with --endpoint for SeaweedFS, MinIO, R2) or --to DIR")
    return S3Target(bucket, endpoint=endpoint, region=region, prefix=prefix) if bucket else DirTarget(Path(to or "."))


@cli.command("sync")
@root_option
@click.option("--bucket", envvar=settings.S3_BUCKET.name, default=None,
              help="Destination bucket ($THERMCAP_S3_BUCKET).")
@click.option("--endpoint", envvar=settings.S3_ENDPOINT.name, default=None,
              help="S3-compatible endpoint ($THERMCAP_S3_ENDPOINT); credentials from AWS_ACCESS_KEY_ID / "
                   "AWS_SECRET_ACCESS_KEY.")
@click.option("--region", envvar=settings.S3_REGION.name, default=settings.S3_REGION.default, show_default=True)
@click.option("--prefix", envvar=settings.S3_PREFIX.name, default=settings.S3_PREFIX.default,
              help="Key prefix in the bucket.")
@click.option("--to", "to_dir", type=click.Path(file_okay=False), default=None,
              help="Instead of a bucket: a folder (a depot share), written part by part.")
@click.option("--session", "sessions", multiple=True, help="Only these sessions (repeat); default: the whole root.")
@click.option("--max-rate", default=None, metavar="RATE",
              help='Bandwidth cap, e.g. 2MB/s, or by local time: "08:00-18:00=512KB/s,4MB/s".')
@click.option("--part-size", default=8, show_default=True,
              type=Number(minimum=5, maximum=5120, integer=True, unit="MiB"), metavar="MiB",
              help="Multipart part size: at most this much is sent again after a drop.")
@click.option("--watch", is_flag=True, help="Keep going: ship segments as they close, take receipts as they come.")
@click.option("--interval", default=10.0, show_default=True, help="--watch: seconds between passes.")
@click.option("--status", "show_status", is_flag=True, help="Only say what is pending, in flight, uploaded, confirmed.")
@click.option("--delete-confirmed", is_flag=True,
              help="Then delete local segments whose receipt names their exact bytes (never inside a protected "
                   "event window).")
@json_option
def sync_cmd(root: str, bucket: str | None, endpoint: str | None, region: str, prefix: str, to_dir: str | None,
             sessions: tuple[str, ...], max_rate: str | None, part_size: int, watch: bool, interval: float,
             show_status: bool, delete_confirmed: bool, as_json: bool) -> None:
    """Ship closed segments, session.json, events and protected windows (those first, then segments oldest
    first) and keep each upload's state on disk: a dropped link or a reboot re-sends at most the part in flight.
    A segment is safe once the cloud's receipt (`thermcap sync-confirm`) names its exact size and sha256."""
    from thermcap.recorder.cli.progress import progress
    from thermcap.recorder.sync.engine import Syncer
    from thermcap.recorder.sync.rate import parse_rate

    try:
        syncer = Syncer(Path(root), _target(bucket, endpoint, region, prefix, to_dir), rate=parse_rate(max_rate),
                        part_size=part_size << 20)
        only = list(sessions) or None
        if show_status:
            st = syncer.status(only)
            syncer.check_receipts()
            st = syncer.status(only)
            click.echo(json.dumps(st.to_dict(), indent=2) if as_json else
                       f"pending {len(st.pending)} ({st.pending_bytes:,} B), in flight {len(st.in_flight)} "
                       f"({st.in_flight_bytes_done:,} of {st.in_flight_bytes:,} B), uploaded {len(st.uploaded)} "
                       f"(waiting for a receipt), confirmed {len(st.confirmed)}")
            return
        stop = threading.Event()

        def asked_to_stop(*_: object) -> None:
            if stop.is_set():  # a second Ctrl-C: now (the journal resumes the part in flight)
                raise KeyboardInterrupt
            stop.set()  # the first: after this pass, exit 0

        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        if watch:
            signal.signal(signal.SIGINT, asked_to_stop)
        while True:
            with progress(as_json=as_json) as bar:
                task = bar.add_task("sync", total=None)

                def shown(key: str, done: int, total: int, bar=bar, task=task) -> None:
                    bar.update(task, description=f"sync {key}", completed=done, total=total)

                try:
                    report = syncer.run_once(only, on_progress=shown)
                    freed = syncer.delete_confirmed() if delete_confirmed else []
                    status = syncer.status(only).to_dict()
                except (ThermcapError, OSError) as exc:
                    if not watch:
                        raise
                    # --watch ends only when asked: a pass that failed is said, and the next one tries
                    click.echo(f"thermcap: this pass stopped: {exc}; the next in {interval:g} s", err=True)
                    if stop.wait(interval):
                        break
                    continue
            out = {**report.__dict__, "freed": freed, "status": status}
            out["status"].pop("objects")
            click.echo(json.dumps(out) if as_json else
                       f"sent {report.sent_bytes:,} B in {report.parts_sent} parts ({report.parts_resent} sent again), "
                       f"{report.objects_done} objects done, {report.confirmed} newly confirmed"
                       + (f", {len(freed)} segments freed" if freed else "")
                       + (f"; stopped early: {report.failed[-1]}" if report.stopped_early else "")
                       + (f"; {len(report.diverged)} confirmed segments changed here since and were not sent "
                          f"again: {', '.join(report.diverged[:3])}" if report.diverged else "")
                       + (f"; {len(report.evicted)} evicted by the ring before they were sent (skipped): "
                          f"{', '.join(report.evicted[:3])}" if report.evicted else ""))
            if not watch or stop.wait(interval):
                break
    except (ThermcapError, OSError) as exc:
        fail(str(exc))
    if not watch and report.stopped_early:
        sys.exit(1)
