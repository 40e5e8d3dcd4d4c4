"""The optical side of a synthetic capture: the RealSense-like depth camera with its errors (`depth`) and the
photogrammetry mesh (`photogrammetry`)."""
