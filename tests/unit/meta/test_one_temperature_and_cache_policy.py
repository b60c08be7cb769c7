"""One temperature path and one cache policy, checked from the code (issue 65's "how a reviewer
can check it"). Every module that turns counts into °C with a model's ``to_celsius`` is listed
here with why; a new one fails until it goes through ``recorder.radiometry.session``
(``SessionTemperatures``: the model version in force and the bad-pixel rule) or is listed with
its reason. Every ``Cache-Control`` header is written by ``api/cache_policy.py``."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ROOMS = ("recorder", "archive", "api", "thermcap")

#: module -> why it may call a model's to_celsius itself
TEMPERATURE_CALLS = {
    "recorder/radiometry/session.py": "the home: SessionTemperatures, the version in force and bad pixels",
    "recorder/exports/render.py": "celsius(frame, model): the model its caller took from SessionTemperatures",
    "api/reading/regions.py": "model_at(i): FrameModel's SessionTemperatures.model_for, per frame",
    "recorder/analysis/detector.py": "the detector's float32 path, the named exception, held by its own tests",
    "recorder/capture/sources/sim.py": "the simulator's own model, making counts, not a product",
    "thermcap/benches/analysis.py": "a benchmark's anchor",
    "archive/formats/hdf5.py": "the LUT of the model recorded, which the file names as version 0",
    "recorder/exports/files.py": "a probe: can this model give °C at all (one zero pixel)",
    "api/routes/sessions.py": "a probe: can this server give °C for the session (one zero pixel)",
    "recorder/importers/run.py": "import-time statistics of the vendor's own model, before any version",
    "recorder/live/publisher.py": "the live view: during capture the model recorded (version 0), in `play` the "
                                  "model and version replay takes from SessionTemperatures.model_for",
    "recorder/reports/quality.py": "the report's slope per count, in the version it measured (model_for)",
}

CALL = re.compile(r"\.to_celsius\(")


def _modules() -> list[Path]:
    return [p for room in ROOMS for p in (ROOT / room).rglob("*.py") if "__pycache__" not in p.parts]


def test_counts_become_celsius_only_where_listed():
    found = {str(p.relative_to(ROOT)) for p in _modules() if CALL.search(p.read_text())}
    models = {f"recorder/radiometry/{m}.py" for m in ("base", "linear", "planck", "lookup")}  # the models themselves
    unlisted = sorted(found - set(TEMPERATURE_CALLS) - models)
    assert not unlisted, f"counts to °C outside the one temperature path: {unlisted}"
    stale = sorted(set(TEMPERATURE_CALLS) - found)
    assert not stale, f"listed but no longer converting: remove from TEMPERATURE_CALLS: {stale}"


def test_every_cache_header_comes_from_the_cache_policy():
    header = re.compile(r"[\"']cache-control[\"']", re.IGNORECASE)
    writers = sorted(str(p.relative_to(ROOT)) for p in _modules() if header.search(p.read_text()))
    # fast_frames sends the header cache_policy.cache_control built; docs.py serves Swagger's own
    # static assets, which hold no session data
    assert writers == ["api/cache_policy.py", "api/fast_frames.py", "api/routes/docs.py"], writers
    assert "cache_control(" in (ROOT / "api/fast_frames.py").read_text()
