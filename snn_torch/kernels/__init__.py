"""The fast paths of ``snn_torch``'s computations, each equal to its torch definition bit for bit:
C kernels (``network``: the recurrent Izhikevich network's substeps and a spiking controller's
control step; ``sigmoid``: the recurrent sigmoid network's updates; their sources in ``csrc/``),
the builder that compiles them once per machine (``build``), and the ``torch.compile`` twin of
the network's substep (``compiled``). Nothing is imported here: each module loads on first use.
"""
