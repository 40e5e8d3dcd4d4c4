"""Hydra plugins of mm2fsk-bench (Hydra instantiates launchers only from the `hydra_plugins` namespace)."""
