"""The Thermal Data ICD as code: file names (names), the sidecar schema and encoder (sidecar),
MCAP topics and message schemas (topics), ICD 5 and 7 quality metrics (quality)."""
