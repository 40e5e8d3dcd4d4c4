"""The read-only data layer: MAROON capture folders in, `methods.domain` types out.

`reader` (captures, frames, meshes, metadata), its guarded I/O (`safe_io`, `safe_pickle` (a restricted unpickler),
`jsonio`, `images`, `limits`), `alignment`, `antennas` (with the QAR50 layout in qar50/), `frames` (frame
selection), `reference_check` and `inspect_capture` (`mm2fsk-inspect`). Nothing here writes into a dataset.
"""
