"""``thermcap report``: reports a thermographer signs."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from thermcap.recorder.cli.options import Number, fail, json_option, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError


@cli.group("report")
def report() -> None:
    """Reports over a recorded session."""


def _reference(value: str, root: str) -> tuple[Path, float | None]:
    from thermcap.recorder.storage.reader import resolve_session

    name, _, temp = value.partition("=")
    try:
        return resolve_session(name, root), float(temp) if temp else None
    except ValueError:
        raise ThermcapError(f"--reference {value!r}: expected SESSION or SESSION=TEMP_C") from None


@report.command("quality")
@click.argument("session")
@root_option
@click.option("--blackbody", type=Number(minimum=-273.15, maximum=5000, unit="°C"), default=None, metavar="TEMP_C",
              help="The session looks at a blackbody at this temperature (else its source's, if it says).")
@click.option("--reference", "references", multiple=True, metavar="SESSION[=TEMP_C]",
              help="Blackbody sessions at other temperatures, for linearity (repeat).")
@click.option("--model-version", type=Number(minimum=0, integer=True), default=None, metavar="N",
              help="Measure temperatures with this radiometric model version (default: the latest covering "
                   "each frame; see `thermcap radiometry`).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for quality.html, .pdf and .json (default: SESSION/report).")
@json_option
def quality_cmd(session: str, root: str, blackbody: float | None, references: tuple[str, ...],
                model_version: int | None, out_dir: str | None, as_json: bool) -> None:
    """The ICD section 5 requirements measured from the session: NETD, FPA uniformity, temporal stability,
    absolute accuracy, linearity and bad pixels, each with its limit and pass, fail or not measurable (and why).
    Exit 1 if a requirement fails."""
    from thermcap.recorder.reports.quality import measure_quality
    from thermcap.recorder.reports.render import write_quality_report
    from thermcap.recorder.storage.reader import resolve_session

    try:
        d = resolve_session(session, root)
        rep = measure_quality(d, blackbody_c=blackbody, references=[_reference(r, root) for r in references],
                              model_version=model_version)
        paths = write_quality_report(rep, Path(out_dir) if out_dir else d / "report")
    except ThermcapError as exc:
        fail(str(exc))
    out = rep.to_dict()
    if as_json:
        click.echo(json.dumps({**out, "files": {k: str(v) for k, v in paths.items()}}, indent=2))
    else:
        for m in out["measurements"]:
            value = "-" if m["value"] is None else f"{m['value']} {m['unit']}"
            click.echo(f"{m['requirement']:20} {value:>14}  {m['limit']:24} {m['verdict']}")
        click.echo(f"temperatures from radiometric model version "
                   f"{', '.join(f'v{v}' for v in out['model_versions'])}")
        click.echo(f"written: {paths['html']}, {paths['pdf']}")
    if not out["passed"]:
        sys.exit(1)


@report.command("inspection")
@click.argument("session")
@root_option
@click.option("--max-findings", type=Number(minimum=0, maximum=1000, integer=True), default=12, show_default=True,
              help="The hottest targets, at most.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for inspection.pdf and .json (default: SESSION/report).")
@json_option
def inspection_cmd(session: str, root: str, max_findings: int, out_dir: str | None, as_json: bool) -> None:
    """Detected hot spots as an inspection PDF: per finding the image with its colour bar and box, max, ΔT to the
    local background, time, position, model version and frame hash, and a provenance block `report verify` checks."""
    from thermcap.recorder.reports.inspection import build_inspection
    from thermcap.recorder.reports.render import write_inspection_report
    from thermcap.recorder.storage.reader import resolve_session

    try:
        d = resolve_session(session, root)
        rep = build_inspection(d, max_findings=max_findings)
        paths = write_inspection_report(rep, Path(out_dir) if out_dir else d / "report")
    except ThermcapError as exc:
        fail(str(exc))
    if as_json:
        click.echo(json.dumps({**rep.to_dict(), "files": {k: str(v) for k, v in paths.items()}}, indent=2))
    else:
        click.echo(f"{len(rep.findings)} findings: {paths['pdf']} (and {paths['json'].name})")


@report.command("verify")
@click.argument("report_file", type=click.Path(dir_okay=False, exists=True))
@root_option
@json_option
def verify_cmd(report_file: str, root: str, as_json: bool) -> None:
    """Recompute every number of an inspection report (its PDF or JSON twin) from the archive; exit 1 if one no
    longer holds."""
    from thermcap.recorder.reports.inspection import verify_inspection

    try:
        res = verify_inspection(report_file, root)
    except ThermcapError as exc:
        fail(str(exc))
    if as_json:
        click.echo(json.dumps({"holds": res.holds, "checks": res.checks}, indent=2))
    else:
        for c in res.checks:
            click.echo(f"{'holds ' if c['holds'] else 'DIFFERS'} frame {c.get('frame', '-')} "
                       f"{c.get('target_id', c.get('check', ''))}: {c['why']}")
        click.echo("the report holds" if res.holds else "the report no longer holds")
    if not res.holds:
        sys.exit(1)
