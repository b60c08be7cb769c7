"""The archive's defaults, in a module with no imports: the ``thermcap`` command shows them in
its help without loading the codecs."""

__all__ = ["DEFAULT_FORMATS"]

#: What ``thermcap archive`` writes when no --formats is given.
DEFAULT_FORMATS = ("png16", "tiff-lzw", "hdf5")
