"""Hot-spot analysis: the detector and session events (detector), re-run offline (offline)."""
