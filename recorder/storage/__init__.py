"""The session folder on disk: layout, lock, the MCAP writer, segments, reader, recover, info."""
