"""Thermal images on the map: a camera's pose from what the file says (``pose``), and where its
image lands on the ground (``footprint``): corners, ground sample distance, an uncertainty from
the pose's own, in the local UTM zone. Exports use them for footprints and map GeoTIFFs."""
