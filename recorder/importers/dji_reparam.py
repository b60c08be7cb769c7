"""Re-parameterising a DJI session after capture, through DJI's SDK.

DJI's curves live in DJI's SDK, so thermcap cannot move a DJI model's emissivity or distance
itself, as it does for FLIR's Planck model. It asks the SDK again instead. Each frame of the
session is rebuilt into the R-JPEG it came from, bit-exact: the stored counts, plus the APP
segments the importer kept (``recorder.importers.dji_rebuild``). The backend measures the rebuilt
file at the new object parameters. The per-count tables are merged into one, and recorded as
a model version (who, when, why, which frames), as any other re-parameterisation. The stored
counts never change, and version 0 stays what the camera measured.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.importers.dji import kept_rjpeg_segments
from thermcap.recorder.importers.dji_rebuild import rebuild_rjpeg
from thermcap.recorder.importers.dji_sdk import DjiBackend, sdk_params_problem
from thermcap.recorder.radiometry import LookupTableModel, model_from_dict
from thermcap.recorder.radiometry.base import TemperatureUnavailable
from thermcap.recorder.radiometry.params import OBJECT_PARAMS, ModelVersion, add_version
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

__all__ = ["DJI_KINDS", "add_sdk_version"]

#: Models whose object parameters only DJI's SDK can apply.
DJI_KINDS = ("dji", "lookup_table")
_BATCH = 96  # files per SDK call, as the importer measures them


def add_sdk_version(session_dir: Path, params: dict[str, float], backend: DjiBackend, *, who: str, why: str,
                    frames: tuple[int, int] | None = None) -> ModelVersion:
    """Measure the session's frames (or ``frames`` [start, end)) at ``params`` with ``backend``
    and record the result as the next model version."""
    if not why.strip():
        raise ValueError("say why the parameters change (it is kept with the version)")
    unknown = sorted(set(params) - set(OBJECT_PARAMS))
    if unknown:
        raise ValueError(f"unknown object parameter {', '.join(unknown)}; use {', '.join(OBJECT_PARAMS)}")
    problem = sdk_params_problem(params)
    if problem:
        raise ValueError(problem)
    base = model_from_dict(read_session_meta(session_dir).get("radiometric_model") or {"kind": "linear"})
    if getattr(base, "kind", "") not in DJI_KINDS:
        raise ValueError(f"{session_dir.name}: a {getattr(base, 'kind', '?')} model, not DJI's; "
                         f"re-parameterise it without the SDK")
    kept = kept_rjpeg_segments(session_dir)
    if not kept:
        raise ThermcapError(f"{session_dir}: no DJI R-JPEG segments are kept with this session (neither in its "
                            f"MCAP source nor in its archive's extras.mcap), so DJI's SDK has nothing to measure")
    derived = base.derived_from if isinstance(base, LookupTableModel) else base.to_dict()
    name = getattr(backend, "name", "DJI SDK").partition(", measured")[0]
    source = f"{name}, measured at {json.dumps(params, sort_keys=True)} (the rest as embedded)"
    table: LookupTableModel | None = None
    batch: list[tuple[int, np.ndarray, str]] = []

    def measure(batch: list[tuple[int, np.ndarray, str]]) -> None:
        nonlocal table
        got = backend.measure([p for _, _, p in batch], params)
        for index, pixels, path in batch:
            temp = got.get(path, "not measured")
            if isinstance(temp, str):
                raise ThermcapError(f"frame {index}: {temp}")
            try:
                one = LookupTableModel.from_measurement(pixels, temp, source=source, derived_from=derived)
            except (TemperatureUnavailable, ValueError) as exc:
                raise ThermcapError(f"frame {index}: {exc}") from None
            merged = one if table is None else table.merged(one)
            if merged is None:
                raise ThermcapError(f"frame {index}: DJI's SDK gives its counts other temperatures than the "
                                    f"session's earlier frames at these parameters; record the frame ranges apart "
                                    f"(--frames)")
            table = merged

    measured = 0
    with tempfile.TemporaryDirectory(prefix="thermcap-dji-") as tmp:
        for f in iter_session_frames(session_dir):
            if frames is not None and not frames[0] <= f.index < frames[1]:
                continue
            if f.log_time not in kept:
                raise ThermcapError(f"frame {f.index}: not imported from a DJI R-JPEG (no DJI segments kept)")
            path = os.path.join(tmp, f"frame{f.index:06d}.jpg")
            Path(path).write_bytes(rebuild_rjpeg(f.pixels, kept[f.log_time][1]))
            batch.append((f.index, f.pixels, path))
            measured += 1
            if len(batch) >= _BATCH:
                measure(batch)
                for _, _, p in batch:
                    os.unlink(p)
                batch = []
        if batch:
            measure(batch)
    if table is None or not measured:
        raise ThermcapError(f"{session_dir}: no frame in {frames} to measure" if frames else
                            f"{session_dir}: the session has no frame")
    return add_version(session_dir, base, params, who=who, why=why, frames=frames, measured=table)
