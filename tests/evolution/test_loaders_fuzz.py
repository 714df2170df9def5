"""The genome and checkpoint loaders against hostile files: every fault is a ``CheckpointError``
naming the file and the field, never another exception (or a crash in a kernel later)."""

import json
import re

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from evolution.checkpoint import CheckpointError, atomic_torch_save
from evolution.genome_io import genome_to_dict, load_genome
from evolution.mutate import mutate_add_connection, mutate_add_node
from evolution.neat import NEAT
from evolution.population import check_invariants
from tests.evolution.helpers import population, small_config

CFG = small_config(node_add_prob=0.8, conn_add_prob=0.8, pop_size=8)
FAST = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _valid() -> dict:
    g, rng = population(CFG, seeds=(0,))
    everyone = torch.ones(1, CFG.pop_size, dtype=torch.bool)
    for _ in range(2):
        g, _ = mutate_add_node(g, CFG, rng, everyone)
        g = mutate_add_connection(g, CFG, rng, everyone)
    return genome_to_dict(g, CFG, 0, int(g.num_genes()[0].argmax()), fitness=1.5)


VALID = _valid()
HIDDEN = next(n["id"] for n in VALID["nodes"] if n["kind"] == "hidden")


def _load(tmp_path, data, name="g.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return load_genome(path, CFG)


def _edit(**changes) -> dict:
    data = json.loads(json.dumps(VALID))
    for key, value in changes.items():
        data[key] = value
    return data


def _conn(**changes) -> dict:
    data = _edit()
    data["connections"][0].update(changes)
    return data


@pytest.mark.parametrize("data, match", [
    (_conn(weight=1e39), rf"weight 1e\+39 lies outside the config's \[{CFG.weight_min_value}, {CFG.weight_max_value}\]"),
    (_conn(weight=CFG.weight_max_value + 0.5), "weight_min_value, weight_max_value"),
    (_conn(weight=10**400), r"weight is 1000.*expected a finite number"),
    (_edit(sigma=CFG.sigma_max_value + 1), f"sigma {CFG.sigma_max_value + 1} lies outside"),
    (_edit(sigma=10**400), "sigma is 1000"),
    (_edit(nodes=[*VALID["nodes"][:-1], {**VALID["nodes"][-1], "kind": "input"}]), "in this layout it is 'hidden'"),
    (_edit(nodes=[*VALID["nodes"], {"id": HIDDEN, "kind": "hidden"}]), f"node {HIDDEN} appears twice"),
    (_edit(layout={**VALID["layout"], "num_nodes": 99}), "layout .* does not match"),
    (_edit(layout={**VALID["layout"], "num_nodes": 10**400}), "layout .* does not match"),
    (_conn(**{"from": 10**400}), r"'from' is 1000.*\.\.\.; expected a node id"),
    (_edit(fitness="high"), "fitness is 'high'"),
])
def test_out_of_range_or_inconsistent_content_is_refused_naming_file_and_field(tmp_path, data, match):
    with pytest.raises(CheckpointError, match=match) as exc:
        _load(tmp_path, data, name="champion.json")
    assert "champion.json" in str(exc.value)


def test_the_valid_genome_loads_and_huge_json_numbers_are_named(tmp_path):
    g = _load(tmp_path, VALID)
    check_invariants(g.gather(torch.zeros(1, CFG.pop_size, dtype=torch.long)), CFG)
    text = re.sub(r'"sigma": [^,}]+', '"sigma": 1' + "0" * 5000, json.dumps(VALID))
    with pytest.raises(CheckpointError, match="g.json.*not valid JSON"):
        _load(tmp_path, text)


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
                    max_leaves=12)


@FAST
@given(path=st.lists(st.sampled_from(["nodes", "connections", "layout", 0, 1, "id", "kind", "from", "to", "weight",
                                      "enabled", "sigma", "version", "format", "num_nodes", "num_inputs"]),
                     min_size=1, max_size=3),
       value=JSON)
def test_fuzzed_genome_files_load_valid_or_raise_checkpoint_error(tmp_path, path, value):
    data = json.loads(json.dumps(VALID))
    holder = data
    for key in path[:-1]:
        try:
            holder = holder[key]
        except (KeyError, IndexError, TypeError):
            break
    try:
        holder[path[-1]] = value
    except (IndexError, TypeError):
        pass
    try:
        g = _load(tmp_path, json.dumps(data, allow_nan=True))
    except CheckpointError as exc:
        assert "g.json" in str(exc)
    else:
        check_invariants(g.gather(torch.zeros(1, CFG.pop_size, dtype=torch.long)), CFG)


@FAST
@given(data=st.binary(max_size=300))
def test_fuzzed_genome_bytes_load_valid_or_raise_checkpoint_error(tmp_path, data):
    (tmp_path / "g.json").write_bytes(data)
    with pytest.raises(CheckpointError, match="g.json"):
        load_genome(tmp_path / "g.json", CFG)


STATE = NEAT(CFG, seeds=[3, 4]).state_dict()
TENSORS = [(k, None) for k in ("species", "best_fitness", "solved_generation")] + [
    (k, sub) for k in ("genomes", "best_genomes", "species_state") for sub in STATE[k]]


def _tensor(draw_shape, dtype_name, fill):
    shape = tuple(draw_shape)
    dtype = getattr(torch, dtype_name)
    return torch.full(shape, fill).to(dtype) if dtype != torch.bool else torch.full(shape, bool(fill))


@FAST
@given(target=st.sampled_from(TENSORS),
       shape=st.lists(st.integers(0, 9), max_size=4),
       dtype=st.sampled_from(["bool", "int32", "int64", "float32", "float64"]),
       fill=st.sampled_from([0, 1, -1, 7, 1e30, float("nan")]),
       scalar=st.sampled_from([None, ("generation", -5), ("generation", 10**400), ("fitness_target", 10**400),
                               ("seeds", [1.5, 2]), ("seeds", [2**64, 1]), ("dtype", "bfloat16"), ("config", [1]),
                               ("device", "tpu"), ("rng", torch.zeros(3)), ("genomes", [])]))
def test_fuzzed_checkpoints_restore_valid_or_raise_checkpoint_error(tmp_path, target, shape, dtype, fill, scalar):
    state = {**STATE, **{k: dict(v) for k, v in STATE.items() if isinstance(v, dict)}}
    key, sub = target
    if fill == float("nan") and dtype in ("bool", "int32", "int64"):
        fill = 0
    if sub is None:
        state[key] = _tensor(shape, dtype, fill)
    else:
        state[key][sub] = _tensor(shape, dtype, fill)
    if scalar is not None:
        state[scalar[0]] = scalar[1]
    path = atomic_torch_save(state, tmp_path / "fuzz.pt")
    try:
        neat = NEAT.restore(path)
    except CheckpointError as exc:
        assert "fuzz.pt" in str(exc)
    else:  # whatever restores must breed without a crash
        neat.tell(torch.zeros(neat.num_runs, CFG.pop_size, dtype=torch.float64))


@FAST
@given(cut=st.integers(0, 10_000), flips=st.lists(st.integers(0, 10**6), max_size=4))
def test_truncated_or_flipped_checkpoint_bytes_raise_checkpoint_error(tmp_path, cut, flips):
    raw = bytearray(atomic_torch_save(STATE, tmp_path / "good.pt").read_bytes())
    for at in flips:
        raw[at % len(raw)] ^= 0x5A
    raw = raw[: len(raw) - cut] if cut else raw
    if bytes(raw) == (tmp_path / "good.pt").read_bytes():
        return  # the flips cancelled out: a valid file
    (tmp_path / "bad.pt").write_bytes(bytes(raw))
    with pytest.raises(CheckpointError, match="bad.pt"):
        NEAT.restore(tmp_path / "bad.pt")


def test_a_generation_past_int64_raises_checkpoint_error(tmp_path):
    # found by the fuzz above: compared with the int64 solved generations, it overflowed in torch
    path = atomic_torch_save({**STATE, "generation": 10**400}, tmp_path / "huge.pt")
    with pytest.raises(CheckpointError, match="generation"):
        NEAT.restore(path)
