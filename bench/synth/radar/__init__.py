"""The radar side of a synthetic capture: the stepped-frequency MIMO signal model (`model`), the scatterers a scene
presents to it (`scene`) and second-order multipath between object parts (`multipath`)."""
