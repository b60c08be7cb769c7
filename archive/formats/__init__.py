"""The archive formats, registered by id (ids never change once files carry them)."""

from thermcap.archive.formats.base import (
           MCAP_SOURCE_COST,
           ArchiveContext,
           ArchiveFormat,
           FileRecord,
           ReadCost,
           format_registry,
           get_format,
           read_cost,
           register_format,
)
from thermcap.archive.formats.hdf5 import Hdf5
from thermcap.archive.formats.temporal import TemporalFrames
from thermcap.archive.formats.tiff_lzw import TiffLzw
from thermcap.archive.formats.zipped import ZippedFrames, zipped_factory

# Read costs, ranked: for one frame a stored-ZIP entry is one ranged read and one decode (PNG's
# libpng first; HTJ2K decodes one at a time), then the MCAP source's chunk, then HDF5 and TIFF,
# whose file structure costs reads of its own; tpred decodes from its key frame. For every frame
# in order, HDF5's whole chunks come first, then PNG, then TIFF's strips.
register_format("png16", zipped_factory("png16"), ReadCost(frame=10, stream=20))
register_format("htj2k", zipped_factory("htj2k"), ReadCost(frame=20, stream=40))
register_format("jpegls", zipped_factory("jpegls"), ReadCost(frame=30, stream=50))
register_format("jxl", zipped_factory("jxl", effort=2), ReadCost(frame=40, stream=60))
register_format("hdf5", Hdf5, ReadCost(frame=60, stream=10))
register_format("tiff-lzw", TiffLzw, ReadCost(frame=70, stream=30))
register_format("tpred", TemporalFrames, ReadCost(frame=80, stream=70))

__all__ = [
           "MCAP_SOURCE_COST",
           "ArchiveContext",
           "ArchiveFormat",
           "FileRecord",
           "Hdf5",
           "ReadCost",
           "TemporalFrames",
           "TiffLzw",
           "ZippedFrames",
           "format_registry",
           "get_format",
           "read_cost",
           "register_format",
]
