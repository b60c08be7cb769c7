"""thermcap archive: lossless repacking, a bit-exact proof of every frame, the manifest, verify,
scrub and storage costs."""
