"""tpred: thermcap's own temporal codec for Gray16 sequences (a frame predicted from the one
before it, residuals entropy-coded with rANS), opt-in and frozen behind its bitstream version.

- ``codec``: the bitstream, the encoder and decoder (groups of pictures);
- ``rans``: the entropy coder; ``key``: key frames; ``filter``: the prediction filters;
- ``kernels``: the numba passes the others call.

``docs/explanation/tpred.md`` says why it exists and where it stands against FFV1 and JPEG-XL.
"""
