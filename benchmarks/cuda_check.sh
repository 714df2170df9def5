#!/usr/bin/env bash
# Issue 8's GPU checks in one short run, for a session lent a GPU (the device tool):
#
#   bash benchmarks/cuda_check.sh          # from the repository root; log in $OUT (or .) as cuda_check.log
#
# Needs python3 with torch (CUDA) and Triton, numpy, scipy, matplotlib, tqdm, networkx and
# pytest, as the lent H200's image has them; the package itself runs from the source tree.
# Prints: the GPU, the CUDA tests (compiled substep against eager on the GPU), the closed loop
# at R x P = 1e6 (one batch) and the other scale rows, compiled (CUDA's default), then the
# same rows eager, for the ratio. Issue 8's CUDA target: 1e10 neuron-substeps/s at 1e6 x 8.
set -uo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
log="${OUT:-.}/cuda_check.log"
rows="1000000x8,100000x8,9000x8,150x8,100000x16,100000x32,100000x64,1000000x16"
{
    nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
    python3 -c "import torch, triton; print('torch', torch.__version__, 'triton', triton.__version__, torch.cuda.get_device_name())"
    python3 -m pytest -q -p no:cacheprovider -o addopts="" -k cuda tests
    python3 benchmarks/scale.py --device cuda --steps 100 --max-memory 65536 --points "$rows"
    python3 benchmarks/scale.py --device cuda --steps 100 --max-memory 65536 --points "$rows" --compile off
} 2>&1 | tee "$log"
