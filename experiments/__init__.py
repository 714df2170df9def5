"""One-off studies behind the docs' reproduction page; not part of the installed package.

Run from the repository root, e.g. ``python -m experiments.tune_ga table2``.
"""
