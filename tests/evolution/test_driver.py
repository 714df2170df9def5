"""The NEAT driver: determinism, batch independence, checkpoints, errors."""

import os
import subprocess
import sys
import textwrap

import pytest
import torch

from evolution.checkpoint import CheckpointError
from evolution.config import ConfigError
from evolution.neat import NEAT, FitnessError
from evolution.population import check_invariants
from evolution.reporters import Checkpointer, StatisticsReporter
from tasks.studies.xor import XOR_CONFIG, xor_fitness
from tests.evolution.helpers import small_config

CFG = small_config(pop_size=30, max_hidden=6, node_add_prob=0.2, conn_add_prob=0.3)


def fitness_fn(genomes):
    """A deterministic fitness that rewards structure and certain weights."""
    w = genomes.effective_weight()
    return (w[..., 0, 3] - (w[..., 1, 3] - 1.0).abs() + 0.3 * genomes.num_hidden(CFG)).double()


def _run(seeds, generations=8, cfg=CFG):
    neat = NEAT(cfg, seeds=seeds)
    neat.run(fitness_fn, generations)
    return neat


def _same(a, b, ra=slice(None), rb=slice(None)):
    for name, t in a.genomes.tensors().items():
        assert torch.equal(t[ra], getattr(b.genomes, name)[rb]), name
    assert torch.equal(a.species[ra], b.species[rb])
    assert torch.equal(a.best_fitness[ra], b.best_fitness[rb])


def test_same_seed_same_result_and_invariants():
    a, b = _run([5, 6]), _run([5, 6])
    _same(a, b)
    check_invariants(a.genomes, CFG)
    c = _run([5, 7])
    assert not torch.equal(a.genomes.weight[1], c.genomes.weight[1])


def test_run_in_a_batch_equals_the_run_alone_bitwise():
    seeds = [11, 12, 13, 14, 15, 16, 17, 18]
    batch = _run(seeds)
    for r in (0, 3, 7):
        alone = _run([seeds[r]])
        _same(batch, alone, ra=slice(r, r + 1))


def test_reproduction_in_run_chunks_equals_one_chunk():
    seeds = [21, 22, 23, 24, 25]
    whole = _run(seeds)
    chunked = NEAT(CFG, seeds=seeds)
    chunked.reproduce_chunk_genomes = 2 * CFG.pop_size  # chunks of 2, 2 and 1 runs
    stats = chunked.add_reporter(StatisticsReporter())
    chunked.run(fitness_fn, 8)
    _same(whole, chunked)
    assert len(stats.rows) == 8 * len(seeds)
    assert not torch.equal(whole.genomes.weight[0], whole.genomes.weight[1])


def test_solved_runs_freeze_and_match_running_alone():
    # XOR: runs solve at different generations, then stop evolving; the others go on.
    from tasks.studies.xor import xor_solved

    seeds = [1, 2, 3, 4, 5, 6]
    solved_fn = lambda g, f: xor_solved(g)  # noqa: E731
    batch = NEAT(XOR_CONFIG, seeds=seeds)
    res = batch.run(xor_fitness, 40, solved_fn=solved_fn)
    solved = [s for s in res.solved_generation.tolist() if s > 0]
    assert len(set(solved)) >= 2, res.solved_generation  # the test needs staggered solutions
    for r in range(len(seeds)):
        alone = NEAT(XOR_CONFIG, seeds=[seeds[r]])
        res_alone = alone.run(xor_fitness, 40, solved_fn=solved_fn)
        assert res_alone.solved_generation.item() == res.solved_generation[r].item()
        assert torch.equal(res_alone.best_genomes.weight[0], res.best_genomes.weight[r])
        assert torch.equal(alone.genomes.weight[0], batch.genomes.weight[r])


def test_checkpoint_resume_in_a_fresh_process_is_bit_identical(tmp_path):
    full = NEAT(CFG, seeds=[21, 22, 23])
    full.run(fitness_fn, 10)
    first = NEAT(CFG, seeds=[21, 22, 23])
    first.add_reporter(Checkpointer(every=5, prefix=tmp_path / "cp-"))
    first.run(fitness_fn, 5)
    assert (tmp_path / "cp-5.pt").exists()
    script = textwrap.dedent(f"""
        import torch
        from evolution.neat import NEAT
        from tests.evolution.test_driver import fitness_fn
        neat = NEAT.restore({str(tmp_path / 'cp-5.pt')!r})
        assert neat.generation == 5
        neat.run(fitness_fn, 5)
        neat.save_checkpoint({str(tmp_path / 'resumed.pt')!r})
    """)
    subprocess.run([sys.executable, "-c", script], check=True, cwd=os.getcwd(),
                   env={**os.environ, "PYTHONPATH": os.getcwd()})
    resumed = NEAT.restore(tmp_path / "resumed.pt")
    assert resumed.generation == full.generation == 10
    _same(resumed, full)
    for name, t in full.species_state.tensors().items():
        got = getattr(resumed.species_state, name)
        cap = min(t.shape[1], got.shape[1]) if t.dim() > 1 else None
        assert torch.equal(t[:, :cap] if cap else t, got[:, :cap] if cap else got), name


def test_state_dict_is_a_snapshot_that_in_place_generations_leave_alone():
    # Once a run is solved the others breed in place, in the whole population: a state dict
    # (and each NEAT restored from it) must own its tensors, or one would write into another.
    neat = NEAT(XOR_CONFIG, seeds=[1, 2, 3])
    g = torch.Generator().manual_seed(0)

    def fitness() -> torch.Tensor:
        return torch.rand(3, XOR_CONFIG.pop_size, generator=g, dtype=torch.float64) * 16

    solved = torch.zeros(3, XOR_CONFIG.pop_size, dtype=torch.bool)
    solved[0, 0] = True
    neat.tell(fitness(), solved)
    neat.tell(fitness())
    state = neat.state_dict()
    before = {k: v.clone() for k, v in state["genomes"].items()}
    f = fitness()
    copies = [NEAT.from_state_dict(state), NEAT.from_state_dict(state), neat]
    for n in copies:
        n.tell(f)
    for name, t in before.items():
        assert torch.equal(state["genomes"][name], t), name
    for other in copies[1:]:
        for name, t in copies[0].genomes.tensors().items():
            assert torch.equal(t, getattr(other.genomes, name)), name
        assert torch.equal(copies[0].species, other.species)


def test_corrupted_or_truncated_checkpoint_names_the_file(tmp_path):
    neat = NEAT(CFG, seeds=[1])
    path = neat.save_checkpoint(tmp_path / "good.pt")
    data = path.read_bytes()
    (tmp_path / "trunc.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="trunc.pt"):
        NEAT.restore(tmp_path / "trunc.pt")
    garbled = bytearray(data)
    for i in range(len(data) // 3, len(data) // 3 + 16):
        garbled[i] ^= 0xFF  # flip bits inside the payload
    (tmp_path / "bad.pt").write_bytes(bytes(garbled))
    with pytest.raises(CheckpointError, match="bad.pt"):
        NEAT.restore(tmp_path / "bad.pt")
    torch.save({"hello": 1}, tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="not an snn-neat checkpoint"):  # no header
        NEAT.restore(tmp_path / "other.pt")
    with pytest.raises(CheckpointError, match="does not exist"):
        NEAT.restore(tmp_path / "missing.pt")


def test_a_checkpoint_whose_population_breaks_an_invariant_is_refused():
    # The compatibility distances take a weight where no gene is as a weight difference, and
    # the kernels as none (evolution.distance), so such a population would speciate
    # differently on the two paths, silently; restoring refuses it instead.
    state = NEAT(CFG, seeds=[1]).state_dict()
    conn = state["genomes"]["conn"]
    i, j = (~conn[0, 0]).nonzero()[0].tolist()
    state["genomes"]["weight"][0, 0, i, j] = 0.5
    with pytest.raises(CheckpointError, match="non-zero where no gene"):
        NEAT.from_state_dict(state, name="damaged")
    state = NEAT(CFG, seeds=[1]).state_dict()
    state["genomes"]["enabled"][0, 0, i, j] = True
    with pytest.raises(CheckpointError, match="enabled but does not exist"):
        NEAT.from_state_dict(state, name="damaged")


def test_a_crash_while_writing_keeps_the_previous_checkpoint(tmp_path, monkeypatch):
    neat = NEAT(CFG, seeds=[1])
    path = neat.save_checkpoint(tmp_path / "cp.pt")
    before = path.read_bytes()
    neat.run(fitness_fn, 1)

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", boom)
    with pytest.raises(OSError, match="disk full"):
        neat.save_checkpoint(path)
    assert path.read_bytes() == before
    assert NEAT.restore(path).generation == 0
    assert not [p for p in tmp_path.iterdir() if p.name != "cp.pt"]  # no temp files left


def test_bad_fitness_is_rejected_with_indices():
    neat = NEAT(CFG, seeds=[1, 2])
    f = torch.zeros(2, 30)
    f[1, 4] = float("nan")
    with pytest.raises(FitnessError, match=r"\[1, 4\]"):
        neat.tell(f)
    with pytest.raises(FitnessError, match="shape"):
        neat.tell(torch.zeros(30))
    assert neat.generation == 0


def test_statistics_reporter_and_csv(tmp_path):
    neat = NEAT(CFG, seeds=[1, 2])
    stats = neat.add_reporter(StatisticsReporter())
    neat.run(fitness_fn, 4)
    assert len(stats.rows) == 8
    best = stats.best_fitness()
    assert best.shape == (4, 2)
    first = fitness_fn(NEAT(CFG, seeds=[1, 2]).genomes).amax(1)
    assert torch.equal(best[0], first)  # generation 0's best per run
    path = stats.save_csv(tmp_path / "stats.csv")
    lines = path.read_text().splitlines()
    assert lines[0].startswith("generation,run,best_fitness") and len(lines) == 9


@pytest.mark.parametrize("field, value, match", [
    ("pop_size", 1, r"pop_size must be in \[2, inf\)"),
    ("node_add_prob", 1.5, r"node_add_prob must be in \[0, 1\]"),
    ("compatibility_threshold", 0.0, r"compatibility_threshold must be in \(0, inf\)"),
    ("max_hidden", 2.5, "max_hidden must be an integer"),
    ("feed_forward", "yes", "feed_forward must be true or false"),
    ("weight_mutate_power", float("nan"), "weight_mutate_power must be a number"),
])
def test_config_validation_names_the_field(field, value, match):
    with pytest.raises(ConfigError, match=match):
        small_config(**{field: value})


def test_complete_extinction_restarts_the_run():
    cfg = small_config(pop_size=20, max_stagnation=1, species_elitism=0, compatibility_threshold=100.0)
    neat = NEAT(cfg, seeds=[4, 5])
    extinct = []

    class Watch(StatisticsReporter):
        def complete_extinction(self, status):
            extinct.extend(status.extinct)

    neat.add_reporter(Watch())
    neat.run(lambda g: torch.zeros(2, 20, dtype=torch.float64), 4)  # nothing ever improves
    assert sorted(set(extinct)) == [0, 1]
    check_invariants(neat.genomes, cfg)
    assert neat.genomes.pop_size == 20 and bool((neat.species >= 0).all())


def test_tqdm_reporter_runs_and_closes(capsys):
    from evolution.reporters import TqdmReporter

    neat = NEAT(CFG, seeds=[1])
    bar = neat.add_reporter(TqdmReporter(total=3))
    neat.run(fitness_fn, 3)
    assert bar.bar is None
    assert "3/3" in capsys.readouterr().err


def test_fractional_or_bool_seeds_and_complex_fitness_are_refused_not_truncated():
    import numpy as np

    for seeds in ([1.5], [True], ["3"]):
        with pytest.raises(ValueError, match="seeds must be non-negative integers"):
            NEAT(CFG, seeds=seeds)
    assert NEAT(CFG, seeds=[np.int64(4)]).rng.seeds == [4]  # numpy integers are integers
    neat = NEAT(CFG, seeds=[1])
    with pytest.raises(FitnessError, match="must be real"):
        neat.tell(torch.zeros(1, 30, dtype=torch.complex128) + 1j)
    assert neat.generation == 0


def test_restoring_a_command_checkpoint_says_what_it_is(tmp_path):
    from evolution.checkpoint import atomic_torch_save, load_checkpoint_dict

    state = NEAT(CFG, seeds=[1]).state_dict()
    path = atomic_torch_save({"format": state["format"], "version": state["version"], "identity": {"task": "table2"},
                              "neat": state, "history": torch.zeros(0, 1)}, tmp_path / "snn.ckpt")
    with pytest.raises(CheckpointError, match=r"snn.ckpt.*snn-neat reproduce .*--resume.*\['neat'\]"):
        NEAT.restore(path)
    assert NEAT.from_state_dict(load_checkpoint_dict(path)["neat"]).generation == 0  # what the message offers


@pytest.mark.parametrize("key, damage, match", [
    ("species", lambda t: t.fill_(99), r"species holds a slot outside"),
    ("species", lambda t: t[:, :5], r"species should be \(1, 30\)"),
    ("species", lambda t: t.int(), r"species should be .*torch.int64"),
    ("best_fitness", lambda t: t.float(), r"best_fitness should be"),
    ("solved_generation", lambda t: t.fill_(7), r"solved_generation lies outside"),
    ("best_genomes.weight", lambda t: t[:, :, :2], r"best_genomes.weight should be"),
    ("species_state.rep_weight", lambda t: t[:, :1], r"species_state.rep_weight should be"),
    ("species_state.next_id", lambda t: t[:0], r"species_state.next_id should be"),
])
def test_a_crafted_checkpoint_with_wrong_shapes_is_refused(key, damage, match):
    state = NEAT(CFG, seeds=[1]).state_dict()
    parent, _, leaf = key.rpartition(".")
    holder = state[parent] if parent else state
    holder[leaf] = damage(holder[leaf])
    with pytest.raises(CheckpointError, match=match):
        NEAT.from_state_dict(state, name="crafted")
    state = NEAT(CFG, seeds=[1]).state_dict()
    state["dtype"] = "manual_seed"
    with pytest.raises(CheckpointError, match="not float32 or float64"):
        NEAT.from_state_dict(state, name="crafted")


def test_statistics_of_runs_still_evolving_after_one_solved_are_their_own():
    # Every child tries to add a node and there is one hidden slot: most splits are refused.
    cfg = small_config(pop_size=12, node_add_prob=1.0, max_hidden=1)
    calls = []

    def solve_run_0(g, f):  # run 0 solves in the first generation; solved_fn sees unsolved runs only
        calls.append(f.shape[0])
        return torch.zeros_like(f, dtype=torch.bool).index_fill_(0, torch.tensor([0]), len(calls) == 1)

    batch = NEAT(cfg, seeds=[1, 2, 3])
    stats = batch.add_reporter(StatisticsReporter())
    batch.run(fitness_fn, 4, solved_fn=solve_run_0)  # run 0 solves at once and is frozen
    alone = NEAT(cfg, seeds=[2, 3])  # runs 1 and 2 evolve as they would alone
    alone_stats = alone.add_reporter(StatisticsReporter())
    alone.run(fitness_fn, 4)
    refused = {(row["generation"], row["run"]): row["split_refused"] for row in stats.rows}
    for row in alone_stats.rows:
        assert refused[(row["generation"], row["run"] + 1)] == row["split_refused"]
    assert all(refused[(g, 0)] == 0 for g in range(4))  # a solved run breeds nothing
    assert calls == [3, 2, 2, 2]  # the frozen run is not judged again
    assert sum(row["split_refused"] for row in alone_stats.rows) > 0  # there was something to count


def test_solved_fn_judges_the_unsolved_runs_only_and_its_answer_is_checked():
    seen = []

    def solve_first_call(g, f):
        seen.append((g.num_runs, tuple(f.shape)))
        return torch.full(f.shape, len(seen) == 1 and g.num_runs == 3, dtype=torch.bool) & (
            torch.arange(f.shape[0]) == 1).unsqueeze(1)

    neat = NEAT(small_config(pop_size=12), seeds=[1, 2, 3])
    neat.run(fitness_fn, 3, solved_fn=solve_first_call)
    assert [s[0] for s in seen] == [3, 2, 2]
    assert neat.solved_generation.tolist() == [-1, 1, -1]
    bad = NEAT(small_config(pop_size=12), seeds=[1])
    with pytest.raises(FitnessError, match="solved_fn must return a bool tensor"):
        bad.run(fitness_fn, 1, solved_fn=lambda g, f: f)  # float-valued answers are refused
