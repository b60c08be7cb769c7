"""The thermographer's tools over stored frames: spots, boxes, line profiles, polygons,
histograms and isotherms (``measure``), on one frame or as a time series over a session."""
