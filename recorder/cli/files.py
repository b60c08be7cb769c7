"""``thermcap import`` and ``export``: camera files in, temperature files out."""

from __future__ import annotations

import json
import os
import sys
from typing import Any

import click

from thermcap.recorder import settings
from thermcap.recorder.cli.options import Number, fail, json_option, parse_instant, root_option
from thermcap.recorder.cli.root import cli
from thermcap.recorder.exceptions import ThermcapError


@cli.command("import")
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@root_option
@click.option("--session", "session_name", default=None,
              help="Session id (suffixed -1, -2 ... when files need several).")
@click.option("--session-per-file", is_flag=True, help="One session per file.")
@click.option("--analysis/--no-analysis", default=True, show_default=True,
              help="Run the hot-spot detector on the frames.")
@click.option("--dji-sdk", default=settings.DJI_SDK.default, show_default=True, envvar=settings.DJI_SDK.name,
              metavar="auto|off|PATH",
              help="DJI temperatures by DJI's own code: auto = dji-thermal-cli if on PATH; off; or the path to "
                   "libdirp (.so/.dll) or a dji-thermal-cli executable. Without one, DJI dirp/girp/hirp frames "
                   "import with no temperature and iirp with an approximate one.")
@click.option("--terraref-variant", type=click.Choice(["pipeline", "physical", "plain"]), default="pipeline",
              show_default=True, help="TERRA-REF Planck form for uncalibrated _ir.bin: pipeline = what every published "
                                      "TERRA-REF product used; physical = the measurement equation inverted properly.")
@click.option("--model", "model_json", default=None, metavar="JSON|FILE",
              help="The camera's radiometric model, for files that carry none (a ROS 2 bag): a model object "
                   "(as session.json's radiometric_model) or a file holding one, e.g. a Lepton in TLinear mode: "
                   "'{\"kind\": \"linear\", \"scale_c_per_count\": 0.01, \"offset_c\": -273.15, "
                   "\"bit_depth\": 16}'.")
@json_option
def import_cmd(paths: tuple[str, ...], root: str, session_name: str | None, session_per_file: bool, analysis: bool,
               dji_sdk: str, terraref_variant: str, model_json: str | None, as_json: bool) -> None:
    """Import FLIR JPEG/FFF/SEQ/CSQ, DJI R-JPEG, TERRA-REF _ir.bin and ICD TIFF/raw files (by content)."""
    from thermcap.recorder.cli.progress import progress
    from thermcap.recorder.importers.dji_sdk import find_backend
    from thermcap.recorder.importers.run import import_paths

    model = None
    if model_json is not None:
        from pathlib import Path

        from thermcap.recorder.radiometry import model_from_dict

        try:
            text = Path(model_json).read_text() if not model_json.lstrip().startswith("{") else model_json
            model = model_from_dict(json.loads(text))
        except (OSError, ValueError, TypeError) as exc:
            fail(f"--model {model_json[:80]}: {exc}")
    backend = find_backend(dji_sdk)
    if backend is not None and not as_json:
        click.echo(f"DJI temperatures by {backend.name}", err=True)

    with progress(as_json=as_json) as bar:
        task = bar.add_task("importing", total=len(paths))
        report = import_paths(list(paths), root, session=session_name, session_per_file=session_per_file,
                              analysis=analysis, dji_sdk=backend,
                              terraref_variant=terraref_variant, on_file=lambda p: bar.advance(task), model=model)
    if as_json:
        click.echo(json.dumps({"files": report.files, "failed": report.failed, "truncated": report.truncated,
                               "dji_sdk": backend.name if backend else None,
                               "sessions": [r.to_dict() for r in report.sessions]}, indent=2))
    else:
        for f in report.files:
            c = f["celsius"]
            temp = (f"{c['min']:.2f}..{c['max']:.2f} C (mean {c['mean']:.2f})"
                    + (" approximate" if c.get("approximate") else "")
                    if c else f"no temperature: {f.get('dji_sdk_error') or f.get('celsius_unavailable')}")
            click.echo(f"{f['path']}: {f['format']} {f['layout'] or ''} {f['width']}x{f['height']} {temp} "
                       f"-> {f.get('session_id')}")
            for key, what in (f.get("notes") or {}).items():
                click.echo(f"  note: {key.replace('_', ' ')}: {json.dumps(what)}")
        for r in report.sessions:
            click.echo(f"session {r.session_id}: {r.frames_written} frames")
        for f in report.failed:
            click.echo(f"error: {f['error']}", err=True)
        for f in report.truncated:
            click.echo(f"error: {f['error']}", err=True)
    # 0: every file imported (with or without temperatures); 1: a file or a session failed, said why
    broken = [r for r in report.sessions if r.error or r.frames_dropped]
    if not as_json:
        for r in broken:
            click.echo(f"error: session {r.session_id}: {'; '.join(r.problems) or r.error}", err=True)
    if report.failed or report.truncated or broken:
        sys.exit(1)


@cli.command("export")
@click.argument("session")
@root_option
@click.option("--to", "kind", type=click.Choice(["celsius-tiff", "kelvin-tiff", "celsius-cog", "map-tiff", "footprints",
                                                "mosaic", "hotspots", "heatmap-png", "icd", "dji-rjpeg"]),
              required=True)
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder (default: SESSION/export/KIND).")
@click.option("--summary", type=click.Choice(["csv", "json"]), default=None,
              help="Also write per-frame surface_temperature statistics.")
@click.option("--palette", default="ironbow", type=click.Choice(["ironbow", "gray", "turbo"]), show_default=True)
@click.option("--range", "range_mode", type=click.Choice(["session", "frame", "fixed"]), default="session",
              show_default=True, help="heatmap-png: one scale for the session, each frame's own, or --min/--max.")
@click.option("--min", "t_min", type=Number(minimum=-273.15, maximum=5000, unit="°C"), default=None,
              help="heatmap-png: the scale's low end, °C (--range fixed).")
@click.option("--max", "t_max", type=Number(minimum=-273.15, maximum=5000, unit="°C"), default=None,
              help="heatmap-png: the scale's high end, °C.")
@click.option("--crs", type=click.Choice(["utm", "4326"]), default=None,
              help="map-tiff of TERRA-REF images: EPSG:4326 as the pipeline publishes (default) or UTM 12N.")
@click.option("--ground-elevation", type=Number(minimum=-500, maximum=9000, unit="m"), default=None, metavar="M",
              help="Maps: the ground's height above sea level (with the file's absolute altitude) instead of the "
                   "take-off point's.")
@click.option("--dem", type=click.Path(dir_okay=False, exists=True), default=None, metavar="GEOTIFF",
              help="Maps: a DEM (any CRS GDAL reads, heights in metres above the geoid): each footprint corner "
                   "lands on the terrain, with the camera's absolute altitude.")
@click.option("--truth", type=click.Path(dir_okay=False, exists=True), default=None,
              help="hotspots: ground-truth points (GeoJSON or latitude,longitude CSV) to match the detections with.")
@click.option("--match-radius", type=Number(minimum=0, above=True, unit="m"), default=3.0, show_default=True,
              help="hotspots --truth: metres.")
@click.option("--colorbar/--no-colorbar", default=True, show_default=True,
              help="heatmap-png: draw the scale into each picture (the range is in its PNG text either way).")
@click.option("--model-version", type=Number(minimum=0, integer=True), default=None,
              help="Temperatures at this radiometric model version (`thermcap radiometry SESSION` lists them; "
                   "default: the latest covering each frame; 0: as recorded).")
@click.option("--bad-pixels", type=click.Choice(["nan", "keep"]), default="nan", show_default=True,
              help="The session's bad pixels: NaN (no temperature; magenta in pictures) or kept as measured.")
@click.option("--frames", "frame_range", default=None, metavar="START:END",
              help="Only frames START..END-1 (numbers from 0; either side may be left out).")
@click.option("--start", default=None, metavar="TIME", help="Only frames from this time: RFC 3339, or seconds "
                                                            "from the first frame.")
@click.option("--end", default=None, metavar="TIME", help="Only frames before this time; as --start.")
@click.option("--allow-approximate", is_flag=True,
              help="Export temperatures a model only approximates (DJI without its SDK), marked APPROXIMATE in "
                   "each file's name, band description and metadata; refused otherwise.")
@json_option
def export_cmd(session: str, root: str, kind: str, out_dir: str | None, summary: str | None, palette: str,
               range_mode: str, t_min: float | None, t_max: float | None, crs: str | None,
               ground_elevation: float | None, dem: str | None, truth: str | None, match_radius: float, colorbar: bool,
               model_version: int | None, bad_pixels: str, frame_range: str | None, start: str | None,
               end: str | None, allow_approximate: bool, as_json: bool) -> None:
    """Export frames as temperature TIFFs, heatmap PNGs, ICD TIFF+JSON pairs or rebuilt DJI R-JPEGs (and a summary)."""
    from thermcap.recorder.exports.files import export_session
    from thermcap.recorder.storage.reader import resolve_session

    try:
        d = resolve_session(session, root)
        if t_min is not None and t_max is not None and range_mode == "session":
            range_mode = "fixed"  # --min and --max alone mean a fixed scale
        select = _selection(d, frame_range, start, end)
        res = export_session(d, kind, out_dir or d / "export" / kind, summary=summary, palette_name=palette,
                             range_mode=range_mode, t_min=t_min, t_max=t_max, colorbar=colorbar,
                             crs=crs or "4326", ground_elevation_m=ground_elevation, truth=truth,
                             match_radius_m=match_radius, dem=dem, model_version=model_version,
                             bad_pixels=bad_pixels, allow_approximate=allow_approximate, select=select)
    except ThermcapError as exc:
        fail(str(exc))
    click.echo(json.dumps(res, indent=2) if as_json else
               f"{res['files']} files in {res['out']}" + (f"; summary {res['summary']}" if res["summary"] else ""))
    if res.get("truth") and not as_json:
        t = res["truth"]
        click.echo(f"ground truth: {t['matched']} of {t['truth']} found within {t['radius_m']} m "
                   f"(recall {t['recall']}), "
                   f"{t['detections'] - t['matched']} detections match none (precision {t['precision']})")
    for r in res["refused"][:5]:
        click.echo(f"warning: {r}", err=True)
    if res["refused"]:
        sys.exit(1)




def _selection(session_dir: Any, frame_range: str | None, start: str | None, end: str | None) -> Any:
    """--frames, --start and --end as a FrameSelection; a malformed one is a ThermcapError."""
    from thermcap.recorder.exports.files import FrameSelection
    from thermcap.recorder.storage.reader import iter_session_frames

    first = stop = None
    if frame_range is not None:
        a, sep, b = frame_range.partition(":")
        try:
            first, stop = (int(a) if a else None), (int(b) if b else None)
        except ValueError:
            raise ThermcapError(f"--frames {frame_range!r}: use START:END, frame numbers from 0") from None
        if not sep or (first is not None and first < 0) or (stop is not None and first is not None and stop <= first):
            raise ThermcapError(f"--frames {frame_range!r}: use START:END with 0 <= START < END")
    t0 = t1 = None
    if start is not None or end is not None:
        first_ns = next((f.log_time for f in iter_session_frames(session_dir)), 0)
        try:
            t0, t1 = parse_instant(start, first_ns, "start"), parse_instant(end, first_ns, "end")
        except ValueError as exc:
            raise ThermcapError(str(exc)) from None
        if t0 is not None and t1 is not None and t1 <= t0:
            raise ThermcapError("--end must be after --start")
    return FrameSelection(first, stop, t0, t1)


@cli.command("radiometry")
@click.argument("session")
@root_option
@click.option("--set", "sets", multiple=True, metavar="NAME=VALUE",
              help="An object parameter (emissivity, reflected_temp_c, object_distance_m, atmospheric_temp_c, "
                   "relative_humidity_pct, ir_window_temp_c, ir_window_transmission); repeat.")
@click.option("--why", default="", help="Why the parameters change (kept with the version).")
@click.option("--frames", default=None, metavar="START:END", help="Only these frames [START, END).")
@click.option("--who", default=lambda: os.environ.get("USER", "unknown"), show_default="$USER")
@click.option("--dji-sdk", "dji_sdk", default="auto", show_default=True, metavar="auto|PATH",
              help="DJI sessions: the SDK that measures the frames again at the new parameters (dji-thermal-cli; "
                   "auto: THERMCAP_DJI_SDK, else dji-thermal-cli on PATH).")
@json_option
def radiometry_cmd(session: str, root: str, sets: tuple[str, ...], why: str, frames: str | None, who: str,
                   dji_sdk: str, as_json: bool) -> None:
    """List a session's radiometric model versions, or add one (--set ... --why ...): the stored
    counts never change; every temperature names the version it used."""
    from thermcap.recorder.importers.dji_reparam import DJI_KINDS, add_sdk_version
    from thermcap.recorder.importers.dji_sdk import find_backend
    from thermcap.recorder.radiometry import model_from_dict
    from thermcap.recorder.radiometry.params import add_version, read_versions
    from thermcap.recorder.storage.reader import read_session_meta, resolve_session

    try:
        d = resolve_session(session, root)
        if sets:
            params = {}
            for item in sets:
                key, sep, value = item.partition("=")
                if not sep:
                    raise ValueError(f"--set {item!r}: use NAME=VALUE")
                params[key.strip()] = float(value)
            span = None
            if frames:
                a, _, b = frames.partition(":")
                span = (int(a), int(b))
            base = model_from_dict(read_session_meta(d).get("radiometric_model") or {"kind": "linear"})
            if getattr(base, "kind", "") in DJI_KINDS:
                backend = find_backend(dji_sdk)
                if backend is None:
                    raise ThermcapError("a DJI session's object parameters are applied by DJI's SDK: install "
                                        "dji-thermal-cli or give --dji-sdk PATH")
                new = add_sdk_version(d, params, backend, who=who, why=why, frames=span)
            else:
                new = add_version(d, base, params, who=who, why=why, frames=span)
            click.echo(json.dumps(new.to_dict(), indent=2) if as_json else
                       f"version {new.version}: {new.params} ({new.why})")
            return
        versions = read_versions(d)
    except (ThermcapError, ValueError) as exc:
        fail(str(exc))
    if as_json:
        click.echo(json.dumps([v.to_dict() for v in versions], indent=2))
        return
    if not versions:
        click.echo("version 0 only: the model as recorded")
    for v in versions:
        click.echo(f"version {v.version} {v.at} by {v.who}: {v.params}"
                   + (f" frames {v.frames[0]}:{v.frames[1]}" if v.frames else "") + f" - {v.why}")
