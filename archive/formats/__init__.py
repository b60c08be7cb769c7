"""The archive formats, registered by id (ids never change once files carry them)."""

from thermcap.archive.formats.base import (
           ArchiveContext,
           ArchiveFormat,
           FileRecord,
           format_registry,
           get_format,
           register_format,
)
from thermcap.archive.formats.hdf5 import Hdf5
from thermcap.archive.formats.temporal import TemporalFrames
from thermcap.archive.formats.tiff_lzw import TiffLzw
from thermcap.archive.formats.zipped import ZippedFrames, zipped_factory

register_format("png16", zipped_factory("png16"))
register_format("tiff-lzw", TiffLzw)
register_format("hdf5", Hdf5)
register_format("jxl", zipped_factory("jxl", effort=2))
register_format("htj2k", zipped_factory("htj2k"))
register_format("jpegls", zipped_factory("jpegls"))
register_format("tpred", TemporalFrames)

__all__ = [
           "ArchiveContext",
           "ArchiveFormat",
           "FileRecord",
           "Hdf5",
           "TemporalFrames",
           "TiffLzw",
           "ZippedFrames",
           "format_registry",
           "get_format",
           "register_format",
]
