"""Reports a thermographer signs: ``quality`` (the ICD section 5 requirements, measured)."""
