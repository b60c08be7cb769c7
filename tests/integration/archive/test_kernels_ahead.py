"""``python -m thermcap.kernels`` compiles every numba kernel into numba's cache, so the next
process (an archive in a container started from the image) loads them instead of compiling:
real interpreters, a real cache folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys

_TPRED_640 = """
import json
import numpy as np
from thermcap.archive.codecs.tpred.codec import TemporalEncoder, decode_records
from thermcap.kernels import _dispatchers
from thermcap.recorder.capture.sources.sim import SimSource
frames = [f.pixels for f in SimSource(width=640, height=512, frames=4, paced=False, seed=2, view="patrol",
                                      shake_px=0.5).frames()]
enc = TemporalEncoder()
records = [enc.encode(f) for f in frames]
assert any(r[4] == 1 and r[23] for r in records), "no predicted record has a filter (its kernels would not run)"
assert all(np.array_equal(a, b) for a, b in zip(frames, decode_records(records)))
misses = sum(sum(d.stats.cache_misses.values()) for d in _dispatchers())
hits = sum(sum(d.stats.cache_hits.values()) for d in _dispatchers())
print(json.dumps({"compiled": misses, "loaded": hits}))
"""


def _run(args: list[str], cache: str) -> dict:
    proc = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "NUMBA_CACHE_DIR": cache})
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_kernels_compiled_ahead_are_loaded_by_the_next_process_not_compiled(tmp_path):
    cache = str(tmp_path / "numba")
    first = _run(["-m", "thermcap.kernels", "--json"], cache)
    assert first["compiled"] > 10 and first["loaded"] == 0  # an empty cache: everything compiled
    assert any(p.suffix == ".nbi" for p in (tmp_path / "numba").rglob("*"))
    again = _run(["-m", "thermcap.kernels", "--json"], cache)
    assert again["compiled"] == 0 and again["loaded"] > 10
    # a full-size tpred sequence in a new process finds every kernel it runs in the cache
    real = _run(["-c", _TPRED_640], cache)
    assert real["compiled"] == 0 and real["loaded"] > 5
