"""``thermcap export``: a session's frames as files for the people downstream.

``celsius-tiff`` / ``kelvin-tiff``: float32 temperature TIFFs through the session's model (the
source position, where one was recorded, in the TIFF's ImageDescription JSON); ``heatmap-png``:
8-bit colour PNGs on one fixed temperature range for the whole session, so colours compare
across frames; ``icd``: the ICD's own pairs, an uncompressed 16-bit TIFF with every mandatory
tag and its JSON sidecar; ``dji-rjpeg``: R-JPEGs rebuilt from imported DJI frames and their kept APP
segments, which DJI's own tools measure as they did the originals. ``summary`` writes per-frame
``surface_temperature`` statistics (CF standard name; cell_methods min, max, mean and
percentiles) as CSV or JSON.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tifffile

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.exports.colorbar import RANGE_MODES, TemperatureRange
from thermcap.recorder.exports.geotiff import geotransform_tags, utm_tags, write_cog, write_temperature_tiff
from thermcap.recorder.exports.percentiles import percentiles
from thermcap.recorder.exports.render import colour_png, frame_range
from thermcap.recorder.icd.names import format_name, iso_utc
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.radiometry import LinearModel, TemperatureUnavailable, model_from_dict
from thermcap.recorder.radiometry.session import APPROXIMATE_NOTE, SessionTemperatures, approximate_frames
from thermcap.recorder.storage.atomic import replacing, write_json_atomic
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

__all__ = ["EXPORT_KINDS", "export_session"]

@dataclass(frozen=True)
class FrameSelection:
    """Which frames an export takes: frame numbers [first, stop) and log times [start_ns, end_ns);
    None: no bound."""

    first: int | None = None
    stop: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None

    def frames(self, session_dir: Path) -> Iterator[Any]:
        for f in iter_session_frames(session_dir):
            if (self.stop is not None and f.index >= self.stop) or (self.end_ns is not None
                                                                    and f.log_time >= self.end_ns):
                return  # frames come in order: nothing later is wanted
            if (self.first is None or f.index >= self.first) and (self.start_ns is None
                                                                   or f.log_time >= self.start_ns):
                yield f


ALL_FRAMES = FrameSelection()

#: Exports of counts, not temperatures: never refused for an approximate model.
_COUNT_KINDS = ("icd", "dji-rjpeg", "footprints")
EXPORT_KINDS = ("celsius-tiff", "kelvin-tiff", "celsius-cog", "map-tiff", "footprints", "mosaic", "hotspots",
                "heatmap-png", "icd", "dji-rjpeg")
_MAP_KINDS = ("map-tiff", "footprints", "mosaic", "hotspots")
PERCENTILES = (5, 25, 50, 75, 95)


def _import_vendor(session_dir: Path) -> dict[int, dict[str, Any]]:
    """Per log time: what an importer kept of the source file (``/import/source`` ``vendor``)."""
    from mcap.reader import make_reader

    out: dict[int, dict[str, Any]] = {}
    for seg in sorted(session_dir.glob("[0-9][0-9][0-9][0-9].mcap")):
        with open(seg, "rb") as f:
            for _, ch, msg in make_reader(f, validate_crcs=True).iter_messages(topics=["/import/source"]):
                out[msg.log_time] = json.loads(json_payload(ch.message_encoding, msg.data)).get("vendor", {}) or {}
    return out


def _positions(session_dir: Path) -> dict[int, dict[str, Any]]:
    """Per log time: the position an importer recorded, where it recorded one."""
    return {t: p for t, v in _import_vendor(session_dir).items() if (p := _position(v)) is not None}


def _position(vendor: dict[str, Any]) -> dict[str, Any] | None:
    """The position an importer recorded: DJI XMP GPS, FLIR's GPSInfo or EXIF GPS, TERRA-REF gantry."""
    xmp = vendor.get("xmp_drone_dji") or {}
    if xmp.get("GpsLatitude") or xmp.get("GpsLongitude"):
        return {"crs": "EPSG:4326", "latitude": xmp.get("GpsLatitude"),
                "longitude": xmp.get("GpsLongitude") or xmp.get("GpsLongtitude"),
                "absolute_altitude_m": xmp.get("AbsoluteAltitude"),
                "relative_altitude_m": xmp.get("RelativeAltitude"),
                "gimbal_yaw_deg": xmp.get("GimbalYawDegree")}
    gps = vendor.get("gps")
    if gps and str(gps.get("datum", "WGS84")).upper().replace("-", "") in ("WGS84", ""):
        return {"crs": "EPSG:4326", "latitude": gps["latitude"], "longitude": gps["longitude"],
                "absolute_altitude_m": gps.get("altitude_m"), "source": gps.get("source")}
    if vendor.get("position_m"):
        return {"crs": "TERRA-REF gantry (m)", **vendor["position_m"]}
    return None


def _name_range(model: Any, vendor: dict[str, Any], temps: np.ndarray | None) -> tuple[float, float]:
    """The scene range an ICD name carries (ICD 2.1): the camera's calibrated range where the file
    says it (FLIR), a linear model's own range, a lookup table's, else the frame's own."""
    from thermcap.recorder.radiometry import LookupTableModel

    if vendor.get("camera_range_c"):
        lo, hi = vendor["camera_range_c"]
        return float(lo), float(hi)
    if isinstance(model, LinearModel):
        return model.temp_min_c, model.temp_max_c
    if isinstance(model, LookupTableModel):
        return min(model.celsius), max(model.celsius)
    if temps is not None and temps.size:
        return float(np.floor(np.nanmin(temps))), float(np.ceil(np.nanmax(temps)))
    return -40.0, 550.0  # no temperature at all (a DJI layout without the SDK): the ICD's widest


def export_session(session_dir: str | Path, kind: str, out_dir: str | Path, *, summary: str | None = None,
                   palette_name: str = "ironbow", on_frame: Callable[[int], None] | None = None,
                   range_mode: str = "session", t_min: float | None = None, t_max: float | None = None,
                   colorbar: bool = True, crs: str = "4326", ground_elevation_m: float | None = None,
                   truth: str | Path | None = None, match_radius_m: float = 3.0,
                   dem: str | Path | None = None, model_version: int | None = None,
                   bad_pixels: str = "nan", allow_approximate: bool = False,
                   select: FrameSelection = ALL_FRAMES) -> dict[str, Any]:
    """``heatmap-png``: one scale for the session (default), each frame's own, or ``fixed``
    (``t_min``..``t_max`` °C); a colour bar drawn in unless ``colorbar`` is off, and the range in
    each PNG's text chunks either way.

    Temperatures come from ``SessionTemperatures``: the model version covering each frame (the
    latest re-parameterisation, or ``model_version``), the session's bad pixels NaN (or kept,
    ``bad_pixels="keep"``); every file says which version and rule it used. Temperatures a model
    only approximates (DJI without its SDK) are refused unless ``allow_approximate``; then every
    file says so in its name, its band description and its metadata."""
    if kind not in EXPORT_KINDS:
        raise ThermcapError(f"unknown export {kind!r}; use one of {', '.join(EXPORT_KINDS)}")
    session_dir, out = Path(session_dir), Path(out_dir)
    meta = read_session_meta(session_dir)
    model = model_from_dict(meta.get("radiometric_model") or {"kind": "linear"})
    try:
        temps_of = SessionTemperatures.of(session_dir, meta, version=model_version, bad_pixels=bad_pixels)
    except ValueError as exc:
        raise ThermcapError(f"{session_dir}: {exc}") from None
    sensor_id = (meta.get("sensor") or {}).get("sensor_id", "SENSOR")
    if kind not in _COUNT_KINDS and not allow_approximate:
        n_frames = int(meta.get("frames_written") or meta.get("frames") or 0)
        approx = approximate_frames(temps_of, n_frames)
        if approx:
            raise ThermcapError(
                f"{session_dir}: {approx} of {n_frames} frames would get approximate temperatures (DJI's "
                f"uncorrected blackbody formula, several °C off DJI's Thermal SDK). Import again with --dji-sdk "
                f"(dji-thermal-cli or libdirp) to have DJI's code measure them, or pass --allow-approximate to "
                f"export them marked APPROXIMATE")
    out.mkdir(parents=True, exist_ok=True)
    if kind == "dji-rjpeg":
        return _export_dji(session_dir, out, on_frame, select)
    if kind in _MAP_KINDS:
        return _export_map(session_dir, kind, out, temps_of, sensor_id, meta, on_frame,
                           MapOptions(crs, ground_elevation_m, dem, truth, match_radius_m), select)
    vendors = _import_vendor(session_dir)
    positions = {t: p for t, v in vendors.items() if (p := _position(v)) is not None}
    if range_mode not in RANGE_MODES:
        raise ThermcapError(f"range must be one of {', '.join(RANGE_MODES)}, got {range_mode!r}")
    if range_mode == "fixed" and (t_min is None or t_max is None or t_max <= t_min):
        raise ThermcapError("a fixed range needs --min and --max, with max above min")
    frames = list(select.frames(session_dir)) if kind == "heatmap-png" else None
    has_temps = _has_temps(model)
    session_rng: TemperatureRange | None = None
    if frames is not None and range_mode == "session":  # one colour scale for the whole session
        parts = [frame_range(temps_of.celsius(f.index, f.pixels).finite() if has_temps
                             else f.pixels.astype(np.float32)) for f in frames]
        if parts:
            session_rng = TemperatureRange(min(p.lo for p in parts), max(p.hi for p in parts), "session",
                                           "°C" if has_temps else "counts")
    written, stats, refused = [], [], []
    for f in frames if frames is not None else select.frames(session_dir):
        ft = None
        try:
            ft = temps_of.celsius(f.index, f.pixels) if kind != "icd" or summary else None
        except TemperatureUnavailable as exc:
            if kind != "icd":
                refused.append(f"frame {f.index}: {exc}")
                continue
        temps = ft.celsius if ft is not None else None
        name = format_name(f.log_time, sensor_id, *_name_range(ft.model if ft else model,
                                                                vendors.get(f.log_time, {}), temps))
        if ft is not None and ft.approximate:
            name += "_APPROXIMATE"
        desc = {"session_id": meta.get("session_id"), "frame_index": f.index,
                **(ft.describe() if ft is not None else {"radiometric_model": model.to_dict()}),
                "position": positions.get(f.log_time)}
        if kind in ("celsius-tiff", "kelvin-tiff", "celsius-cog"):
            assert temps is not None  # a missing temperature was refused above
            kelvin = kind == "kelvin-tiff"
            data = temps + np.float32(273.15) if kelvin else temps
            path = out / f"{name}.{'kelvin' if kelvin else 'celsius'}.{'cog.' if kind == 'celsius-cog' else ''}tiff"
            units = "K" if kelvin else "degC"
            pos = positions.get(f.log_time)
            write_temperature_tiff(path, data, units=units, description=json.dumps({**desc, "units": units}),
                                   metadata={"session_id": desc["session_id"], "frame_index": f.index,
                                             "time": iso_utc(f.log_time),
                                             "model_version": desc.get("model_version"),
                                             "bad_pixels": desc.get("bad_pixels"),
                                             "radiometric_model": desc["radiometric_model"],
                                             "temperature_quality": desc.get("temperature_quality")},
                                   geo_tags=geotiff_tags(pos, data.shape), position=pos, cog=kind == "celsius-cog")
        elif kind == "heatmap-png":
            src = temps if temps is not None else f.pixels.astype(np.float32)
            if range_mode == "fixed" and t_min is not None and t_max is not None:
                rng = TemperatureRange(t_min, t_max, "fixed")
            else:
                rng = session_rng or frame_range(ft.finite() if ft is not None else src, "frame",
                                                 "°C" if temps is not None else "counts")
            path = out / f"{name}.png"
            said = {"thermcap:model_version": str(ft.model_version), "thermcap:bad_pixels": ft.rule,
                    **({"thermcap:temperature_quality": APPROXIMATE_NOTE} if ft.approximate else {})} \
                if ft is not None else None
            path.write_bytes(colour_png(src, rng, palette_name, colorbar=colorbar, level=6, text=said))
        else:
            path = out / f"{name}.tiff"
            tifffile.imwrite(path, np.ascontiguousarray(f.pixels, dtype=np.uint16), photometric="minisblack",
                             byteorder="<", compression=None, metadata=None, rowsperstrip=f.pixels.shape[0])
            (out / f"{name}.json").write_bytes(f.sidecar or b"{}")
        written.append(path.name)
        if ft is not None and summary:
            good = ft.finite()  # no statistic takes in a bad pixel
            pct = percentiles(good, PERCENTILES)
            stats.append({"frame_index": f.index, "time": desc.get("time") or iso_utc(f.log_time), "file": path.name,
                          "model_version": ft.model_version, "bad_pixels_excluded": ft.bad_pixels,
                          "surface_temperature_mean": round(float(good.mean()), 4),
                          "surface_temperature_min": round(float(good.min()), 4),
                          "surface_temperature_max": round(float(good.max()), 4),
                          **{f"surface_temperature_p{p}": round(float(v), 4) for p,
                             v in zip(PERCENTILES, pct, strict=True)},
                          "units": "degC"})
        if on_frame:
            on_frame(len(written))
    if summary:
        _write_summary(out, summary, stats, meta)
    return {"out": str(out), "kind": kind, "files": len(written), "refused": refused,
            "summary": (str(out / f"summary.{summary}") if summary else None)}


@dataclass(frozen=True)
class MapOptions:
    """How map exports place frames: the CRS of TERRA-REF tiles, the ground (a flat plane at the
    take-off point, at ``ground_elevation_m``, or a DEM's terrain) and the ground truth to match."""

    crs: str = "4326"
    ground_elevation_m: float | None = None
    dem: str | Path | None = None
    truth: str | Path | None = None
    match_radius_m: float = 3.0


def _export_map(session_dir: Path, kind: str, out: Path, temps_of: SessionTemperatures, sensor_id: str,
                meta: dict[str, Any],
                on_frame: Callable[[int], None] | None, opts: MapOptions,
                select: FrameSelection = ALL_FRAMES) -> dict[str, Any]:
    """``footprints``: one GeoJSON feature per frame whose pose places it; ``map-tiff``: each such
    frame as a °C GeoTIFF (``recorder.maps``): a drone image in its UTM zone; a TERRA-REF gantry
    image rotated and placed as the TERRA-REF pipeline does, in EPSG:4326 as it publishes (or UTM
    12N with ``crs="utm"``). A frame that cannot be placed is refused with what its file lacks,
    never placed by a guess."""
    from thermcap.recorder.maps.footprint import FootprintRefused, footprint
    from thermcap.recorder.maps.mosaic import hot_spot_points
    from thermcap.recorder.maps.pose import PoseMissing, pose_from_vendor
    from thermcap.recorder.maps.terrain import Dem, DemError
    from thermcap.recorder.maps.terraref import UTM_12N, gantry_footprint

    crs, truth = opts.crs, opts.truth
    dem = Dem.from_file(opts.dem) if opts.dem is not None else None
    vendors = _import_vendor(session_dir)
    features: list[dict[str, Any]] = []
    written: list[str] = []
    refused: list[str] = []
    tiles: list[tuple[int, Any, np.ndarray]] = []  # mosaic: (frame, footprint, °C)
    frame_times: dict[int, str] = {}
    frame_versions: dict[int, int] = {}  # mosaic: the model version each frame's temperatures used
    for f in select.frames(session_dir):
        h, w = f.pixels.shape
        vendor = vendors.get(f.log_time, {})
        pixels = f.pixels
        gantry = gantry_footprint(vendor, iso_utc(f.log_time)[:10]) if vendor.get("position_m") else None
        if gantry is not None:
            pixels = np.rot90(f.pixels, 3)  # as the pipeline writes it: 640 rows north-south
            ph, pw = pixels.shape
            props = {"frame_index": f.index, "time": iso_utc(f.log_time), **gantry.to_properties()}
            ring_ll = [(gantry.lon_min, gantry.lat_max), (gantry.lon_max, gantry.lat_max),
                       (gantry.lon_max, gantry.lat_min), (gantry.lon_min, gantry.lat_min)]
            tags = geotransform_tags(gantry.geotransform_4326(pw, ph), 4326) if crs != "utm" else \
                geotransform_tags(gantry.geotransform_utm(pw, ph), UTM_12N)
        else:
            try:
                fp = footprint(pose_from_vendor(vendor, w, h, ground_elevation_m=opts.ground_elevation_m, dem=dem),
                               dem=dem)
            except (PoseMissing, FootprintRefused, DemError) as exc:
                refused.append(f"frame {f.index}: {exc}")
                continue
            props = {"frame_index": f.index, "time": iso_utc(f.log_time), **fp.to_properties()}
            ring_ll, tags = fp.corners_lonlat, utm_tags(fp)
        if kind == "footprints":
            ring = [list(c) for c in ring_ll] + [list(ring_ll[0])]
            features.append({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
                             "properties": props})
        elif kind == "hotspots":
            if gantry is not None:
                refused.append(f"frame {f.index}: hot spots on the map are for drone images")
                continue
            targets = f.sidecar_dict().get("targets") or []
            if not targets:
                continue
            try:  # the hot spots' temperatures in the version asked for, not the detector's at capture
                ft = temps_of.celsius(f.index, f.pixels)
            except TemperatureUnavailable as exc:
                refused.append(f"frame {f.index}: {exc}")
                continue
            for pt in hot_spot_points(fp, targets, ft.celsius):
                features.append({"type": "Feature",
                                 "geometry": {"type": "Point", "coordinates": [pt["longitude"], pt["latitude"]]},
                                 "properties": {"frame_index": f.index, "time": iso_utc(f.log_time), **pt,
                                                "model_version": ft.model_version,
                                                **({"temperature_quality": APPROXIMATE_NOTE}
                                                   if ft.approximate else {})}})
        elif kind == "mosaic":
            if gantry is not None or not fp.nadir:
                refused.append(f"frame {f.index}: not near nadir, so not in the mosaic (its pixels are not on "
                               f"one scale; export it with --to map-tiff)")
                continue
            try:
                ft = temps_of.celsius(f.index, f.pixels)
            except TemperatureUnavailable as exc:
                refused.append(f"frame {f.index}: {exc}")
                continue
            tiles.append((f.index, fp, ft.celsius))
            frame_times[f.index] = iso_utc(f.log_time)
            frame_versions[f.index] = ft.model_version
        else:
            try:
                ft = temps_of.celsius(f.index, f.pixels)
            except TemperatureUnavailable as exc:
                refused.append(f"frame {f.index}: {exc}")
                continue
            temps = np.rot90(ft.celsius, 3) if gantry is not None else ft.celsius  # as ``pixels`` is laid
            name = format_name(f.log_time, sensor_id, *_name_range(ft.model, vendor, temps))
            path = out / f"{name}{'_APPROXIMATE' if ft.approximate else ''}.map.tiff"
            write_temperature_tiff(path, temps, units="degC", geo_tags=tags,
                                   description=json.dumps({"units": "degC", **props}),
                                   metadata={"session_id": meta.get("session_id"), "frame_index": f.index,
                                             "time": iso_utc(f.log_time), "footprint": props,
                                             **ft.describe()})
            written.append(path.name)
        if on_frame:
            on_frame(len(features) + len(written))
    if kind in ("footprints", "hotspots"):
        path = out / f"{kind}.geojson"
        path.write_text(json.dumps({"type": "FeatureCollection", "features": features}, indent=1))
        written = [path.name] if features else []
    report = None
    if kind == "hotspots" and truth is not None:
        from thermcap.recorder.maps.truth import compare_with_truth, read_truth

        spots = [f["properties"] for f in features]
        if not spots:
            raise ThermcapError(f"{session_dir}: no hot spot on the map to compare with {truth}")
        epsg = features[0]["properties"].get("epsg") or 4326
        report = compare_with_truth(spots, read_truth(truth), int(epsg), opts.match_radius_m).to_dict()
        (out / "hotspots.truth.json").write_text(json.dumps(report, indent=1))
        written.append("hotspots.truth.json")
    if kind == "mosaic":
        approx = any(getattr(temps_of.model_for(i)[0], "approximate", False) for i, _, _ in tiles)
        written = _write_mosaic(out, tiles, frame_times, frame_versions, meta, temps_of.bad_pixels, approx) \
            if tiles else []
    return {"out": str(out), "kind": kind, "files": len(written), "features": len(features), "refused": refused,
            "summary": None, **({"truth": report} if report is not None else {})}


def _write_mosaic(out: Path, tiles: list[tuple[int, Any, np.ndarray]], frame_times: dict[int, str],
                  frame_versions: dict[int, int], meta: dict[str, Any], bad_pixel_rule: str,
                  approximate: bool = False) -> list[str]:
    from thermcap.recorder.maps.mosaic import build_mosaic

    try:
        mosaic = build_mosaic(tiles)
    except ValueError as exc:
        raise ThermcapError(str(exc)) from None
    rule = "each cell: the nearest pixel of the image whose centre is nearest (one real measurement)"
    common = {"session_id": meta.get("session_id"), "gsd_m": mosaic.gsd_m, "blending": rule,
              "model_versions": sorted({frame_versions[i] for i in mosaic.frames}),
              "bad_pixels": {"rule": bad_pixel_rule, "meaning": "NaN: no temperature (the session's bad-pixel map)"
                             if bad_pixel_rule == "nan" else "kept as the sensor measured them"},
              **({"temperature_quality": APPROXIMATE_NOTE} if approximate else {})}
    write_cog(out / "mosaic.tiff", mosaic.temps, geotransform=mosaic.geotransform, epsg=mosaic.epsg, units="degC",
              metadata={**common, "sources": "mosaic.sources.tiff"}, nodata=float("nan"))
    write_cog(out / "mosaic.sources.tiff", mosaic.sources, geotransform=mosaic.geotransform, epsg=mosaic.epsg,
              units=None, metadata={**common, "value": "frame index of each cell (-1: none)"}, nodata=-1)
    (out / "mosaic.frames.json").write_text(json.dumps(
        {"epsg": mosaic.epsg, "gsd_m": mosaic.gsd_m, "blending": rule,
         "frames": [{"frame_index": i, "time": frame_times[i], "model_version": frame_versions[i]}
                    for i in mosaic.frames]}, indent=1))
    return ["mosaic.tiff", "mosaic.sources.tiff", "mosaic.frames.json"]


def _export_dji(session_dir: Path, out: Path, on_frame: Callable[[int], None] | None,
                select: FrameSelection = ALL_FRAMES) -> dict[str, Any]:
    """R-JPEGs rebuilt from the archive for DJI's own tools (see ``recorder.importers.dji_rebuild``)."""
    from thermcap.recorder.importers.dji import kept_rjpeg_segments
    from thermcap.recorder.importers.dji_rebuild import rebuild_rjpeg

    kept = kept_rjpeg_segments(session_dir)
    written, refused = [], []
    for f in select.frames(session_dir):
        if f.log_time not in kept:
            refused.append(f"frame {f.index}: not imported from a DJI R-JPEG (no DJI segments kept)")
            continue
        name, blob = kept[f.log_time]
        path = out / name
        if path.name in written or not name or "/" in name or name.startswith("."):
            path = out / f"frame{f.index:06d}_{Path(name).name or 'dji'}.jpg"
        try:
            path.write_bytes(rebuild_rjpeg(f.pixels, blob))
        except ValueError as exc:
            refused.append(f"frame {f.index}: {exc}")
            continue
        written.append(path.name)
        if on_frame:
            on_frame(len(written))
    return {"out": str(out), "kind": "dji-rjpeg", "files": len(written), "refused": refused, "summary": None}


def geotiff_tags(position: dict[str, Any] | None, shape: tuple[int, int]) -> list[tuple]:
    """GeoTIFF tags for a frame taken at a known WGS 84 position: one tie point, the image centre
    at the camera's longitude, latitude and altitude (EPSG:4326), which GDAL reads as a GCP. No
    pixel scale is written: a footprint would need the lens's field of view and the view angle,
    which the files do not carry reliably, and a wrong scale would be worse than none."""
    if not position or position.get("crs") != "EPSG:4326":
        return []
    try:
        lat, lon = float(position["latitude"]), float(position["longitude"])
    except (TypeError, ValueError, KeyError):
        return []
    try:
        alt = float(position.get("absolute_altitude_m") or 0.0)
    except ValueError:
        alt = 0.0
    h, w = shape
    tiepoint = (w / 2.0, h / 2.0, 0.0, lon, lat, alt)
    # GeoKeyDirectory: version 1.1.0, 3 keys: GTModelType=Geographic(2), GTRasterType=PixelIsArea(1),
    # GeographicType=WGS 84 (4326).
    keys = (1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326)
    return [(33922, "d", 6, tiepoint, True), (34735, "H", len(keys), keys, True)]


def _has_temps(model) -> bool:
    try:
        model.to_celsius(np.zeros((1, 1), np.uint16))
        return True
    except TemperatureUnavailable:
        return False


def _write_summary(out: Path, fmt: str, stats: list[dict[str, Any]], meta: dict[str, Any]) -> None:
    path = out / f"summary.{fmt}"
    if fmt == "json":
        doc = {"standard_name": "surface_temperature", "units": "degC",
               "cell_methods": "area: mean area: minimum area: maximum area: percentile",
               "session_id": meta.get("session_id"), "radiometric_model": meta.get("radiometric_model"),
               "frames": stats}
        write_json_atomic(path, doc, fsync=False, indent=1)
    elif fmt == "csv":
        with replacing(path, fsync=False, newline="") as f:
            if stats:
                w = csv.DictWriter(f, fieldnames=list(stats[0]))
                w.writeheader()
                w.writerows(stats)
    else:
        raise ThermcapError(f"--summary must be csv or json, got {fmt!r}")
