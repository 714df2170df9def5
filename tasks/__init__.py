"""Control tasks, the paper's experiments and the ``snn-neat`` command."""
