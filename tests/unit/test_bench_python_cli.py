"""``thermcap bench python`` is registered and documents its goals."""

from click.testing import CliRunner

from thermcap.cli import cli


def test_bench_python_is_listed():
    r = CliRunner().invoke(cli, ["bench", "python", "-h"])
    assert r.exit_code == 0 and "Zarr endpoint vs h5py" in r.output
