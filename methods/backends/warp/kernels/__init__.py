"""The Warp kernels and functions, one module per concern and nothing else (as NVIDIA newton lays them out): the
correlation, FSK, prior rasterisation, hull fill, tensor-core tables, column-separable BP and BP_max's search.
The modules one level up launch them."""
