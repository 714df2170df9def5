"""NEAT on population tensors (see DESIGN.md, "Population as tensors")."""
