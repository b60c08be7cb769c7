"""Background work over a data root: the archiving worker (worker) and retention (retention)."""
