"""The domain types every floor stands on (the reader in bench, the methods, the metrics): captures and their
pixel grid (`capture`), the antenna array (`antennas`), frame transforms (`transforms`) and the dataset error
(`errors`). Plain data and arithmetic: numpy only, no file is read here.

Why here: the top level (bench/ methods/ metrics/) is fixed; the harness `bench` is the upper floor and must not be
imported by methods or metrics, and metrics evaluate what methods return, so the floor under both is a
subpackage of `methods` that imports nothing else of it (`methods/__init__` loads its own modules lazily).
"""
