"""Reading sessions for the API: the copies a served session has, read through the archive's one
checked reader (``archive.reading.copies``); each session's frames file; search; regions."""
