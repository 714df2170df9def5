"""The C fast paths of ``evolution``, each equal to its torch definition bit for bit: breeding
(``breed``: parent selection, crossover, mutation, species assignment; the tensor reference is
``evolution.reproduce`` and ``evolution.speciate``), selection and species bookkeeping
(``select``), whole episodes in one native call (``episodes``) and the binding of a plant's native
step (``native_plant``); their sources in ``csrc/``, built by ``snn_torch.kernels.build``.
Nothing is imported here: each module loads on first use.
"""
