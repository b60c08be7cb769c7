"""thermcap's compiled kernels, compiled ahead of their first use: ``python -m thermcap.kernels``.

tpred, the TIFF-LZW encoder, the frame summary and the detector run loops compiled by numba
(``cache=True``). A process loads them from numba's cache in about 0.3 s; on a machine whose
cache has not seen them (a new install, a container started from an image), the first archive
compiles them instead, 3-10 s of one core, and a short session's tpred ran at a third of its
rate (65 against 187 fps, ``thermcap bench temporal``'s fresh-process line). Running this once
where the package is installed, as a build step (the Dockerfile does), moves that to the build.

It records a small simulated session into a temporary folder and archives it in every format
that has kernels, with the read-back that decodes each frame, so each kernel is compiled for the
argument types the real paths give it (numba compiles per type signature, not per size), then
tries the detector's. The cache is numba's own: beside the code where that folder is writable,
else the user's cache, or ``NUMBA_CACHE_DIR`` when set (the image sets it, since the package
folder is not the running user's).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from types import ModuleType

from thermcap.recorder.install_hint import install_command

__all__ = ["KernelReport", "compile_all", "kernel_modules", "main"]

_MODULES = ("thermcap.archive.codecs.tpred.rans", "thermcap.archive.codecs.tpred.kernels",
            "thermcap.archive.codecs.tpred.key", "thermcap.archive.codecs.tpred.filter", "thermcap.archive.lzw_kernels",
            "thermcap.archive.summary_kernels", "thermcap.recorder.analysis.detector_jit")
_FORMATS = ["tiff-lzw", "tpred"]  # the formats whose writers and readers run compiled loops


@dataclass(frozen=True)
class KernelReport:
    kernels: int  # compiled functions used, each for one or more type signatures
    compiled: int  # signatures compiled in this run (not in the cache)
    loaded: int  # signatures loaded from the cache
    seconds: float


def kernel_modules() -> list[ModuleType]:
    """The modules that hold numba kernels (imported: that alone compiles nothing)."""
    from importlib import import_module

    return [import_module(name) for name in _MODULES]


def _dispatchers() -> list[object]:
    from numba.core.registry import CPUDispatcher

    seen: dict[int, object] = {}
    for mod in kernel_modules():
        for value in vars(mod).values():
            if isinstance(value, CPUDispatcher):
                seen[id(value)] = value
    return list(seen.values())


def compile_all() -> KernelReport:
    """Run every kernel once, on the types the archive and the detector give it; see the module
    docstring. Raises ``ImportError`` without numba (the ``archive`` extra)."""
    import numba  # noqa: F401 - the extra's absence is said here, before any work

    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.analysis import detector_kernels
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    t = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="thermcap-kernels-") as tmp:
        # a pan (block modes, motion), a shutter (intra records), defects (the key's list) and a
        # shake (sub-pixel shifts and filters)
        src = SimSource(width=96, height=64, frames=90, fps=60.0, paced=False, seed=1, view="patrol",
                        shutter_every_s=0.5, pixel_fpn_mk=15.0, shake_px=0.5)
        rec = Recorder(src, tmp, session_id="kernels", analysis=False, recover_leftovers=False)
        res = rec.run()
        if res.error is not None:
            raise RuntimeError(f"the kernels' warm-up session did not record: {res.error}")
        archive_session(rec.session_dir, _FORMATS)
    # a sequence encoded on its own (bench temporal, a library caller): tpred keeps its own watch
    # for defects, which the archive's encoder (given the session's defects) does not run
    from thermcap.archive.codecs.tpred.codec import TemporalEncoder

    enc = TemporalEncoder()
    for frame in SimSource(width=96, height=64, frames=3, paced=False, seed=1).frames():
        enc.encode(frame.pixels)
    if not detector_kernels.available():
        raise RuntimeError("the detector's kernels do not compile on this machine (the detector keeps numpy)")
    compiled = loaded = kernels = 0
    for d in _dispatchers():
        stats = d.stats  # type: ignore[attr-defined]
        misses, hits = sum(stats.cache_misses.values()), sum(stats.cache_hits.values())
        kernels += bool(misses or hits)
        compiled += misses
        loaded += hits
    return KernelReport(kernels=kernels, compiled=compiled, loaded=loaded,
                        seconds=round(time.perf_counter() - t, 2))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m thermcap.kernels",
                                     description="Compile thermcap's numba kernels into numba's cache now.")
    parser.add_argument("--json", action="store_true", help="print machine-readable JSON")
    args = parser.parse_args(argv)
    try:
        report = compile_all()
    except ImportError as exc:
        print(f"thermcap: nothing to compile: numba is not installed ({exc}); "
              f"`{install_command('archive')}` brings it", file=sys.stderr)
        return 1
    except RuntimeError as exc:
        print(f"thermcap: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(asdict(report)))
    else:
        print(f"{report.kernels} kernels: {report.compiled} signatures compiled, {report.loaded} loaded from "
              f"numba's cache, in {report.seconds} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

