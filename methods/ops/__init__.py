"""Operations the methods share: the correlation API and its float64 reference (`correlate`), range compression
(`range_compression`), the depth peak (`depth_peak`), depth filtering (`filtering`), frequency configurations
(`frequencies`) and stage timing (`timing`).
"""
