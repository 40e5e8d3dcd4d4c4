"""The per-pixel depth prior of MM-2FSK/MM-3FSK on the radar grid: building it from the depth camera or a mesh
(`priors`), the image a method receives (`image`), and triangle rasterisation with hole filling (`raster`).
"""
