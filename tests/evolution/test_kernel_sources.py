"""The C sources of the evolution kernels against what the Python side assumes of them."""

import ctypes
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from evolution import rng
from evolution.config import NEATConfig
from evolution.kernels import breed as breed_kernel
from evolution.kernels import episodes as episodes_kernel
from evolution.kernels import select as select_kernel
from snn_torch.kernels.build import parse_prototypes, parse_structs
from tests.evolution import kernel_entry_points as kernel_tests

CSRC = Path(breed_kernel.__file__).resolve().parent / "csrc"


def _c_array(text: str, name: str) -> list[float]:
    body = re.search(rf"static const double {name}\[\d+\] = \{{([^}}]*)\}};", text).group(1)
    return [float.fromhex(x) for x in body.replace("\n", " ").split(",") if x.strip()]


def _c_define(text: str, name: str) -> float:
    return float.fromhex(re.search(rf"#define {name} (\S+)", text).group(1))


def test_box_muller_constants_are_the_python_ones():
    # The torch and C normals agree bit for bit only while both use the same coefficients.
    text = (CSRC / "box_muller.h").read_text()
    assert _c_array(text, "BM_LOG_C") == rng._LOG_C
    assert _c_array(text, "BM_COS_C") == rng._COS_C
    assert _c_array(text, "BM_SIN_C") == rng._SIN_C
    assert _c_define(text, "BM_LN2") == rng._LN2
    assert _c_define(text, "BM_SQRT_HALF") == rng._SQRT_HALF
    assert _c_define(text, "BM_TWO_PI") == rng.TWO_PI


@pytest.mark.skipif(shutil.which("nm") is None, reason="no nm to list a library's symbols")
@pytest.mark.parametrize("module", [breed_kernel, select_kernel, kernel_tests])
def test_a_library_exports_exactly_what_its_header_declares(module):
    # Undeclared exports would be callable with unchecked signatures; test entry points in a
    # production library would be compiled by every build.
    name, _, header = module.LIBRARY
    lib = module.library() if module is kernel_tests else module._library()
    if lib is None:
        pytest.skip("no C compiler: kernels unavailable")
    out = subprocess.run(["nm", "-D", "--defined-only", str(lib.path)], capture_output=True, text=True,
                         check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.split()[1:2] == ["T"]}
    assert exported == set(parse_prototypes(header.read_text())), name


# Each Python mirror of a kernel's parameter struct, and the header and name of the C struct.
TEST_CSRC = Path(kernel_tests.__file__).resolve().parents[1] / "csrc"
STRUCTS = [
    (select_kernel.SelectParams, CSRC / "select.h", "select_params"),
    (select_kernel.SelectParentsIO, CSRC / "select.h", "select_parents_io"),
    (select_kernel.OffspringIO, CSRC / "select.h", "offspring_io"),
    (select_kernel.RepsIO, CSRC / "select.h", "reps_io"),
    (breed_kernel.BreedParams, CSRC / "breed.h", "breed_params"),
    (breed_kernel.GeneSet, CSRC / "breed.h", "gene_set"),
    (breed_kernel.BreedIO, CSRC / "breed.h", "breed_io"),
    (breed_kernel.AssignIO, CSRC / "breed.h", "assign_io"),
    (episodes_kernel.EpisodesIO, CSRC / "episodes.h", "episodes_io"),
    (episodes_kernel.SpikingParams, CSRC / "episodes.h", "spiking_params"),
    (episodes_kernel.SigmoidParams, CSRC / "episodes.h", "sigmoid_params"),
    (kernel_tests.DistancesIO, TEST_CSRC / "kernel_entry_points.h", "distances_io"),
]


def _ctype(t: object) -> tuple:
    """A field's ctypes type, comparable: arrays as (element, length)."""
    return (t._type_, t._length_) if isinstance(t, type) and issubclass(t, ctypes.Array) else (t,)


@pytest.mark.parametrize(("cls", "header", "c_name"), STRUCTS, ids=[c for _, _, c in STRUCTS])
def test_a_python_struct_mirrors_its_c_struct(cls, header, c_name):
    # Names, order and types: ctypes lays the fields out as the C compiler does only if they agree.
    c_fields = parse_structs(header.read_text())[c_name]
    assert [(n, _ctype(t)) for n, t in cls._fields_] == [(n, _ctype(t)) for n, t in c_fields]


def test_every_struct_of_the_headers_has_a_mirror():
    declared = {(h, name) for h in {h for _, h, _ in STRUCTS} for name in parse_structs(h.read_text())}
    assert declared == {(h, c) for _, h, c in STRUCTS}


def test_a_kernel_struct_needs_every_field_by_name():
    params = select_kernel.select_params(NEATConfig())
    fields = {name: getattr(params, name) for name, _ in params._fields_}
    select_kernel.SelectParams(**fields)
    with pytest.raises(TypeError, match=r"missing fields \['penalty'\]"):
        select_kernel.SelectParams(**{k: v for k, v in fields.items() if k != "penalty"})
    with pytest.raises(TypeError, match=r"unknown \['penalti'\]"):
        select_kernel.SelectParams(**fields, penalti=0.5)
