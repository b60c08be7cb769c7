"""Files for other tools: temperature TIFFs, heatmaps and ICD pairs (files), rendering (render),
rebuilt DJI R-JPEGs (rjpeg)."""
