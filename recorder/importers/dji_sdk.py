"""Optional DJI Thermal SDK backends: real temperatures for DJI R-JPEGs, measured by DJI's code.

DJI's conversion for dirp, girp and hirp (and the corrections for iirp) depend on tables inside
DJI's proprietary SDK, so thermcap never computes them itself. Where the user has the SDK, we ask
it: ``dji-thermal-cli`` (a pure-Python port of the SDK, AGPL, installed separately: it runs as a
program, never imported) or DJI's own ``libdirp`` shared library at a path the user gives (through
ctypes; ``dirp_measure_ex`` at the file's embedded parameters). Nothing is downloaded.

A backend measures whole R-JPEG files, because that is the SDK's input; the importer then turns each
temperature image into a per-count :class:`~recorder.radiometry.LookupTableModel`, checked exact.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Protocol

import numpy as np

from thermcap.recorder import settings
from thermcap.recorder.exceptions import ThermcapError

__all__ = ["CLI_PARAMS", "ENV_VAR", "DjiBackend", "DjiSdkError", "DjiThermalCli", "LibDirp", "find_backend",
           "sdk_params_problem"]

ENV_VAR = settings.DJI_SDK.name


class DjiSdkError(ThermcapError):
    """The backend itself cannot be used (missing, wrong library, failed to start)."""


class DjiBackend(Protocol):
    name: str  # software and version, recorded with every table it measures

    def measure(self, paths: list[str], params: Mapping[str, float] | None = None) -> dict[str, np.ndarray | str]:
        """float32 (H, W) temperatures in C at each file's embedded parameters (or at the object
        parameters ``params``, thermcap's names, where given), or why not."""
        ...


#: thermcap's object parameters -> dji-thermal-cli's flags (its units: metres, percent, °C).
CLI_PARAMS = {"emissivity": "--emissivity", "reflected_temp_c": "--reflected-temp",
              "object_distance_m": "--distance", "relative_humidity_pct": "--humidity",
              "atmospheric_temp_c": "--ambient-temp"}


def sdk_params_problem(params: Mapping[str, float]) -> str | None:
    """Why DJI's SDK cannot take these object parameters, or None."""
    bad = sorted(set(params) - set(CLI_PARAMS))
    if bad:
        return f"DJI's SDK takes {', '.join(CLI_PARAMS)}, not {', '.join(bad)}"
    return None


class DjiThermalCli:
    """``dji-thermal-cli process`` over a batch of files (one process start per batch: it takes
    about half a second to start, a survey has thousands of images)."""

    def __init__(self, executable: str, jobs: int | None = None) -> None:
        self.executable = executable
        self.jobs = jobs or min(os.cpu_count() or 1, 4)
        try:
            out = subprocess.run([executable, "--version"], capture_output=True, text=True, timeout=60)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise DjiSdkError(f"{executable}: cannot run dji-thermal-cli ({exc})") from None
        version = (out.stdout or out.stderr).strip().split()
        if out.returncode != 0 or not version:
            raise DjiSdkError(f"{executable}: `--version` failed ({(out.stderr or out.stdout).strip()[:200]})")
        self.name = f"dji-thermal-cli {version[-1]} (DJI Thermal SDK port), measured at the embedded parameters"

    def measure(self, paths: list[str], params: Mapping[str, float] | None = None) -> dict[str, np.ndarray | str]:
        import tifffile

        if not paths:
            return {}
        problem = sdk_params_problem(params or {})
        if problem:
            return {p: problem for p in paths}
        with tempfile.TemporaryDirectory(prefix="thermcap-dji-") as tmp:
            src, dst = Path(tmp, "in"), Path(tmp, "out")
            src.mkdir()
            names = {}
            for i, path in enumerate(paths):  # numbered links: two files may share a name
                link = src / f"f{i:06d}.jpg"
                os.symlink(os.path.abspath(path), link)
                names[path] = link.stem
            given = dict(params or {})
            cmd = [self.executable, "process", "--input-dir", str(src), "--output-dir", str(dst),
                   "--distance", repr(float(given.pop("object_distance_m"))) if "object_distance_m" in given
                   else "embedded", "--output", "temp_c:tiff", "--compression", "none",
                   "--jobs", str(self.jobs), "--quiet"]
            for name, value in sorted(given.items()):
                cmd += [CLI_PARAMS[name], repr(float(value))]
            try:
                run = subprocess.run(cmd, capture_output=True, text=True, timeout=120 + 10 * len(paths))
            except subprocess.TimeoutExpired:
                return {p: f"{self.name}: timed out" for p in paths}
            log = (run.stdout + run.stderr).splitlines()
            out: dict[str, np.ndarray | str] = {}
            for path, stem in names.items():
                tif = dst / f"{stem}_temp_c.tiff"
                if tif.exists():
                    out[path] = tifffile.imread(tif).astype(np.float32, copy=False)
                else:
                    said = [ln.strip() for ln in log if stem in ln]
                    out[path] = f"dji-thermal-cli could not measure it: {said[0] if said else 'no output'}"
            return out


class _Resolution(ctypes.Structure):
    _fields_ = [("width", ctypes.c_int32), ("height", ctypes.c_int32)]


class LibDirp:
    """DJI's libdirp (Thermal SDK v1.x) through ctypes: ``dirp_create_from_rjpeg``,
    ``dirp_get_rjpeg_resolution``, ``dirp_measure_ex`` and ``dirp_destroy``, as in DJI's
    ``dirp_api.h``. The SDK loads its layout plugins (libv_*.so) from the library's own folder."""

    def __init__(self, path: str) -> None:
        try:
            self.folder = os.path.dirname(os.path.abspath(path))
            lib = ctypes.CDLL(os.path.abspath(path), mode=ctypes.RTLD_GLOBAL)  # its plugins link against it
            self._create = lib.dirp_create_from_rjpeg
            self._resolution = lib.dirp_get_rjpeg_resolution
            self._measure = lib.dirp_measure_ex
            self._destroy = lib.dirp_destroy
        except (OSError, AttributeError) as exc:
            raise DjiSdkError(f"{path}: not a usable DJI libdirp ({exc})") from None
        self._create.argtypes = [ctypes.c_char_p, ctypes.c_int32, ctypes.POINTER(ctypes.c_void_p)]
        self._resolution.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Resolution)]
        self._measure.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_float), ctypes.c_int32]
        self._destroy.argtypes = [ctypes.c_void_p]
        for fn in (self._create, self._resolution, self._measure, self._destroy):
            fn.restype = ctypes.c_int32
        version = ""
        if hasattr(lib, "dirp_get_api_version"):
            class _Version(ctypes.Structure):
                _fields_ = [("api", ctypes.c_uint32), ("magic", ctypes.c_char * 8)]

            v = _Version()
            lib.dirp_get_api_version.argtypes = [ctypes.POINTER(_Version)]
            lib.dirp_get_api_version.restype = ctypes.c_int32
            if lib.dirp_get_api_version(ctypes.byref(v)) == 0:
                version = f" API 0x{v.api:x}"
        self.name = f"DJI libdirp{version} ({os.path.basename(path)}), dirp_measure_ex at the embedded parameters"

    def _measure_one(self, data: bytes) -> np.ndarray | str:
        handle = ctypes.c_void_p()
        rc = self._create(data, len(data), ctypes.byref(handle))
        if rc != 0:
            return f"libdirp refused the file (dirp_create_from_rjpeg returned {rc})"
        try:
            res = _Resolution()
            rc = self._resolution(handle, ctypes.byref(res))
            if rc != 0 or not (0 < res.width <= 8192 and 0 < res.height <= 8192):
                return f"libdirp gave no resolution (rc {rc}, {res.width}x{res.height})"
            out = np.empty((res.height, res.width), dtype=np.float32)
            rc = self._measure(handle, out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)), out.nbytes)
            if rc != 0:
                return f"libdirp could not measure it (dirp_measure_ex returned {rc})"
            return out
        finally:
            self._destroy(handle)

    def measure(self, paths: list[str], params: Mapping[str, float] | None = None) -> dict[str, np.ndarray | str]:
        if params:  # dirp_set_measurement_params is not wired here (no libdirp to prove it against)
            return {p: "object parameters go through dji-thermal-cli; libdirp measures at the embedded ones only"
                    for p in paths}
        # DJI's SDK finds libv_list.ini and its plugins from the working directory on some
        # platforms: run inside the library's folder (import reads files single-threaded here).
        contents: dict[str, bytes | str] = {}
        for p in paths:
            try:
                contents[p] = Path(p).read_bytes()
            except OSError as exc:
                contents[p] = f"cannot read it again for the SDK ({exc.strerror or exc})"
        cwd = os.getcwd()
        os.chdir(self.folder)
        try:
            return {p: data if isinstance(data, str) else self._measure_one(data) for p, data in contents.items()}
        finally:
            os.chdir(cwd)


def find_backend(spec: str | None = "auto") -> DjiBackend | None:
    """``auto``: the ``THERMCAP_DJI_SDK`` setting, else ``dji-thermal-cli`` on PATH, else none;
    ``off``: none; anything else is a path to libdirp (``.so``/``.dll``/``.dylib``) or to a
    ``dji-thermal-cli`` executable. A path that does not work is an error, never a silent fallback."""
    if spec in (None, "", "auto"):
        spec = settings.DJI_SDK.text()
        if spec == "auto":
            found = shutil.which("dji-thermal-cli")
            return DjiThermalCli(found) if found else None
    if spec == "off":
        return None
    if not os.path.exists(spec) and shutil.which(spec) is None:
        raise DjiSdkError(f"{spec}: no such DJI SDK (give libdirp's path, a dji-thermal-cli executable, auto or off)")
    if Path(spec).suffix.lower() in (".so", ".dll", ".dylib") or ".so." in Path(spec).name:
        return LibDirp(spec)
    return DjiThermalCli(shutil.which(spec) or spec)
