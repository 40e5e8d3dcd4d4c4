"""Radar imaging methods (BP, 2FSK, 3FSK, MM-2FSK) on one shared correlation backend."""
