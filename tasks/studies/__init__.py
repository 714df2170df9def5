"""Reproducible experiments: seeded batches of runs that write tables and figures."""
