"""Metrics of the MAROON evaluation: one-sided Chamfer distances (C_g, C_s) and projective errors (P, P_e)."""
