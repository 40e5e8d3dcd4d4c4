"""The Warp backend (methods.backends): kernels apart from the code that launches them, as NVIDIA newton lays out.

Kernel modules (only `@wp.kernel` / `@wp.func`, named by what they compute): `correlation_kernels`,
`prior_kernels`, `fsk_kernels`. Launching and host code: `runtime` (wp.init), `frames` (frame cache and buffer
pool), `correlation`, `prior`, `fsk`; `backend.WarpBackend` ties them to one device.
"""
