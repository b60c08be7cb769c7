"""Which extra brings a missing module: the base install is what a vehicle needs, and a command
that needs more says what to install instead of a traceback."""

from __future__ import annotations

from thermcap.recorder.install_hint import install_command

__all__ = ["EXTRA_FOR", "missing_extra_message"]

#: a module's top-level import name -> (the distribution, the extra that installs it)
EXTRA_FOR: dict[str, tuple[str, str]] = {
    "h5py": ("h5py", "archive"), "numba": ("numba", "archive"), "obstore": ("obstore", "archive"),
    "xxhash": ("xxhash", "archive"),
    "fastapi": ("fastapi", "server"), "starlette": ("fastapi", "server"), "uvicorn": ("uvicorn", "server"),
    "sqlalchemy": ("SQLAlchemy", "server"), "alembic": ("alembic", "server"),
    "swagger_ui_bundle": ("swagger-ui-bundle", "server"), "httptools": ("httptools", "server"),
    "pyarrow": ("pyarrow", "server"),
    "boto3": ("boto3", "sync"), "botocore": ("boto3", "sync"),
    "psycopg": ("psycopg", "fleet"), "distributed": ("distributed", "fleet"),
    "pyproj": ("pyproj", "maps"), "rasterio": ("rasterio", "maps"),
    "matplotlib": ("matplotlib", "reports"), "foxglove": ("foxglove-sdk", "live"),
    "xarray": ("xarray", "python"), "dask": ("dask", "python"), "zarr": ("zarr", "python"),
    "fsspec": ("fsspec", "python"), "aiohttp": ("aiohttp", "python"), "httpx": ("httpx", "python"),
    "kerchunk": ("kerchunk", "python"),
}


def missing_extra_message(exc: ModuleNotFoundError, command: str | None = None) -> str | None:
    """What to tell the user for a module thermcap's extras provide; None for any other module
    (a bug, to be reported as one)."""
    top = (exc.name or "").split(".")[0]
    if top not in EXTRA_FOR:
        return None
    dist, extra = EXTRA_FOR[top]
    what = f"`thermcap {command}`" if command else "this"
    return (f"{what} needs {dist}, which the base install leaves out; install the extra: "
            f"{install_command(extra)} (or the extra all, for every command)")
