"""The Warp backend (methods.backends): kernels apart from the code that launches them, as NVIDIA newton lays out.

Kernel modules (only `@wp.kernel` / `@wp.func`, named by what they compute) in `kernels/`: `correlation`, `fsk`,
`prior`, `hull_fill`, `tables`, `columns`, `search`, `nearest`. Launching and host code here: `runtime` (wp.init),
`frames` (frame cache and buffer pool), `correlation`, `prior`, `fsk`, `hull_fill`, `frame_graph` (a new frame as
one CUDA graph), `columns` (column-separable BP), `search` (BP_max's search on the device), `nearest` (the metrics'
nearest points); `backend.WarpBackend` ties them to one device.
"""
