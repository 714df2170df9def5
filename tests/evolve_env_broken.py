"""A module that fails on import, for ``snn-neat evolve evolve_env_broken:Task``'s error line."""

raise RuntimeError("broken on purpose")
