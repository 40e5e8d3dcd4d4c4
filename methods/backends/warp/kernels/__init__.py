"""The Warp kernels and functions, one module per concern and nothing else (as NVIDIA newton lays them out): the
correlation, FSK, prior rasterisation, hull fill, tensor-core tables, column-separable BP, BP_max's search and the
metrics' nearest points. The modules one level up launch them."""
