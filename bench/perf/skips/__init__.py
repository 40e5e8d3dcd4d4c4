"""The skips' benchmarks: every skip off and on per catalogue object on the CPU (`cpu`), on fresh frames on a Warp
device (`gpu`), and the public reference kernels' full computation they are compared with (`reference`)."""
