"""The closed-loop C kernels against the torch reference loop."""

import shutil

import pytest
import torch

from evolution.neat import NEAT
from tasks.cartpole import DEFAULT_PLANT, PlantError
from tasks.controllers import SigmoidPolicy, SigmoidSpec, SpikingPolicy, SpikingSpec, closed_loop
from tasks.experiments.cartpole import controller_config, nonmarkov_fitness, nonmarkov_start

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler on this machine: the torch loop is used instead")


def _evolved(controller, generations=4):
    # A few generations in, so the batch holds hidden nodes and recurrent connections.
    cfg = controller_config(controller, pop_size=60)
    neat = NEAT(cfg, seeds=[11])
    fit = nonmarkov_fitness(controller, cfg)
    for _ in range(generations):
        neat.tell(neat.evaluate_active(fit, neat.ask()))
    return neat.ask(), cfg


def _as(genomes, dtype):
    g = genomes.clone()
    for name, t in g.tensors().items():
        if t.is_floating_point():
            setattr(g, name, t.to(dtype))
    return g


def _policy(controller, genomes, cfg, fused):
    if controller == "snn":
        return SpikingPolicy(genomes, cfg, SpikingSpec(), 0.01, DEFAULT_PLANT, use_fused=fused)
    return SigmoidPolicy(genomes, cfg, SigmoidSpec(), DEFAULT_PLANT, tau_s=0.01, use_fused=fused)


@pytest.mark.parametrize("controller", ["snn", "sigmoid"])
def test_float64_kernel_equals_torch_loop(controller):
    g, cfg = _evolved(controller)
    g = _as(g, torch.float64)
    B = g.num_runs * g.pop_size
    start = nonmarkov_start(B, dtype=torch.float64)
    fused = _policy(controller, g, cfg, True)
    assert fused.loop_fused
    steps_fused, _ = closed_loop(fused, start, tau_s=0.01, max_steps=400)
    steps_ref, _ = closed_loop(_policy(controller, g, cfg, False), start, tau_s=0.01, max_steps=400)
    assert steps_ref.float().mean() > 20  # not a batch of instant failures
    # In float64 the C library's sin/cos/exp and torch's differ far below anything a spike notices.
    assert torch.equal(steps_fused, steps_ref)


def test_float32_kernel_agrees_with_torch_loop_to_rounding():
    g, cfg = _evolved("snn")
    B = g.num_runs * g.pop_size
    start = nonmarkov_start(B)
    steps_fused, _ = closed_loop(_policy("snn", g, cfg, True), start, tau_s=0.01, max_steps=400)
    steps_ref, _ = closed_loop(_policy("snn", g, cfg, False), start, tau_s=0.01, max_steps=400)
    # One ulp in sin or exp can move a spike by a substep, and the episode diverges from there;
    # most rows stay identical and the population statistics agree.
    assert (steps_fused == steps_ref).float().mean() >= 0.7
    assert abs(steps_fused.float().mean() - steps_ref.float().mean()) <= 0.05 * steps_ref.float().mean()


@pytest.mark.parametrize("controller", ["snn", "sigmoid"])
def test_row_result_does_not_depend_on_batch(controller):
    g, cfg = _evolved(controller)
    B = g.num_runs * g.pop_size
    all_steps, _ = closed_loop(_policy(controller, g, cfg, True), nonmarkov_start(B), tau_s=0.01, max_steps=600)
    for i in (0, 7, B - 1):
        one = g.gather(torch.tensor([[i]]))
        alone, _ = closed_loop(_policy(controller, one, cfg, True), nonmarkov_start(1), tau_s=0.01, max_steps=600)
        assert alone.item() == all_steps[i].item()


def test_nan_from_plant_names_the_row():
    g, cfg = _evolved("sigmoid", generations=0)
    start = nonmarkov_start(g.pop_size)
    start[3, 1] = float("nan")
    with pytest.raises(PlantError, match=r"\[3\]"):
        closed_loop(_policy("sigmoid", g, cfg, True), start, tau_s=0.01, max_steps=10)


def test_kernels_can_be_turned_off(monkeypatch):
    import snn_torch._cbuild as cbuild

    monkeypatch.setenv("SNN_NEAT_FUSED", "0")
    monkeypatch.setattr(cbuild, "_cache", {})
    g, cfg = _evolved("snn", generations=0)
    assert not _policy("snn", g, cfg, True).loop_fused


def _markov_evolved(dtype):
    from tasks.experiments.cartpole import markov_config, markov_fitness

    cfg = markov_config("snn", pop_size=30)
    neat = NEAT(cfg, seeds=[3], dtype=dtype)
    fit = markov_fitness("snn", cfg, max_steps=300)
    for _ in range(3):
        neat.tell(fit(neat.ask()))
    return neat.ask(), cfg


@pytest.mark.parametrize("spec_kw", [{}, {"decoder": "output_neuron"}, {"rate_window_steps": 3, "input_rate_max_hz": 2000.0}])
def test_markov_kernel_equals_torch_reference_float64(spec_kw):
    """The Markov C kernel and the torch reference (``act``) draw the same input spikes and
    balance every genome for the same number of steps."""
    from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec
    from tasks.experiments.cartpole import markov_start

    g, cfg = _markov_evolved(torch.float64)
    spec = MarkovSpikingSpec(**spec_kw)
    B = g.num_runs * g.pop_size
    start = markov_start(B, dtype=torch.float64)
    fused = MarkovSpikingPolicy(g, cfg, spec, 0.02, DEFAULT_PLANT)
    assert fused.loop_fused
    steps_fused, _ = closed_loop(fused, start, tau_s=0.02, max_steps=150)
    reference = MarkovSpikingPolicy(g, cfg, spec, 0.02, DEFAULT_PLANT, use_fused=False)
    steps_ref, _ = closed_loop(reference, start, tau_s=0.02, max_steps=150)
    assert len(set(steps_ref.tolist())) > 3  # genomes that differ, some of which last
    assert torch.equal(steps_fused, steps_ref)


def test_torch_genome_keys_equal_the_kernels():
    from tasks.counter_rng import fnv1a_keys
    from tasks.fused_loop import genome_keys

    x = torch.randn(7, 5, 5, generator=torch.Generator().manual_seed(0))
    assert torch.equal(fnv1a_keys(x), genome_keys(x))
    assert len(set(fnv1a_keys(x).tolist())) == 7
    assert torch.equal(fnv1a_keys(x[3:4]), fnv1a_keys(x)[3:4])


def _random_genomes(n_nodes, batch, seed=0):
    """Random recurrent networks of ``n_nodes`` nodes (2 inputs, 1 output), float64."""
    from evolution.config import NEATConfig
    from evolution.population import Genomes

    cfg = NEATConfig(num_inputs=2, num_outputs=1, num_bias=0, max_hidden=n_nodes - 3, pop_size=batch)
    gen = torch.Generator().manual_seed(seed)
    conn = torch.rand(1, batch, n_nodes, n_nodes, generator=gen) < 0.4
    conn[..., :, :2] = False  # nothing feeds an input
    w = torch.where(conn, torch.randn(1, batch, n_nodes, n_nodes, generator=gen, dtype=torch.float64) * 2.0, 0.0)
    g = Genomes(weight=w, conn=conn, enabled=conn.clone(), node=torch.ones(1, batch, n_nodes, dtype=torch.bool),
                sigma=torch.full((1, batch), 0.005, dtype=torch.float64))
    return g, cfg


@pytest.mark.parametrize("controller", ["snn", "sigmoid"])
@pytest.mark.parametrize("n_nodes", [6, 14, 20, 27])
def test_kernel_equals_torch_loop_at_padded_and_unpadded_sizes(controller, n_nodes):
    """14 and 20 nodes run padded to 16 and 24, 27 at its own size: the padding changes no number."""
    g, cfg = _random_genomes(n_nodes, 64, seed=n_nodes)
    start = nonmarkov_start(64, dtype=torch.float64)
    fused = _policy(controller, g, cfg, True)
    assert fused.loop_fused
    steps_fused, _ = closed_loop(fused, start, tau_s=0.01, max_steps=300)
    steps_ref, _ = closed_loop(_policy(controller, g, cfg, False), start, tau_s=0.01, max_steps=300)
    assert len(set(steps_ref.tolist())) > 3  # networks that differ, so a mix-up would show
    assert torch.equal(steps_fused, steps_ref)


def test_markov_row_result_does_not_depend_on_batch_or_lane():
    """Rows share a thread's lanes and move between them as episodes end; a row's result is
    still what it is alone, in any order of the batch."""
    from tasks.controllers import MarkovSpikingPolicy, MarkovSpikingSpec
    from tasks.experiments.cartpole import markov_start

    g, cfg = _markov_evolved(torch.float32)
    B = g.num_runs * g.pop_size

    def steps(genomes):
        n = genomes.num_runs * genomes.pop_size
        policy = MarkovSpikingPolicy(genomes, cfg, MarkovSpikingSpec(), 0.02, DEFAULT_PLANT)
        assert policy.loop_fused
        return closed_loop(policy, markov_start(n), tau_s=0.02, max_steps=400)[0]

    all_steps = steps(g)
    assert len(set(all_steps.tolist())) > 3
    reverse = torch.arange(B - 1, -1, -1).unsqueeze(0)
    assert torch.equal(steps(g.gather(reverse)), all_steps.flip(0))
    for i in (0, 5, B - 1):
        assert steps(g.gather(torch.tensor([[i]]))).item() == all_steps[i].item()


def test_vectorised_sincos_equals_libm_rounded_to_float():
    """The float sigmoid loop's sin and cos of the pole angle (vectorised over lanes) must be
    libm's double sin and cos rounded to float, bit for bit: random floats at many scales,
    a sample of every bit pattern, the floats next to multiples of pi/2, and the edge cases."""
    import ctypes
    import math

    import tasks.fused_loop as fl

    assert fl.loop_available()
    fn = fl._lib.sincos_check
    fn.restype = None
    fn.argtypes = [ctypes.c_void_p] * 5 + [ctypes.c_int64]
    g = torch.Generator().manual_seed(0)
    parts = [(torch.rand(200_000, generator=g, dtype=torch.float64) * 2 - 1).mul(scale).float()
             for scale in (1e-6, 0.05, 0.25, 1.0, 4.0, 100.0, 4000.0, 1e5)]
    bits = torch.arange(0, 2**32, 65537, dtype=torch.int64)
    parts.append(torch.where(bits >= 2**31, bits - 2**32, bits).to(torch.int32).view(torch.float32))
    k = (torch.arange(-2600, 2600, dtype=torch.float64) * (math.pi / 2)).float()
    parts += [k, torch.nextafter(k, torch.full_like(k, math.inf)), torch.nextafter(k, torch.full_like(k, -math.inf))]
    parts.append(torch.tensor([0.0, -0.0, float("inf"), float("-inf"), float("nan"), 4096.0, -4096.0, 1e-30, -1e-38,
                               1e-45]))
    x = torch.cat(parts).contiguous()
    ours_s, ours_c, libm_s, libm_c = (torch.empty_like(x) for _ in range(4))
    fn(x.data_ptr(), ours_s.data_ptr(), ours_c.data_ptr(), libm_s.data_ptr(), libm_c.data_ptr(), x.numel())
    for ours, libm in ((ours_s, libm_s), (ours_c, libm_c)):
        same = ours.view(torch.int32) == libm.view(torch.int32)
        assert bool(same.all()), x[~same][:5]


def test_vectorised_expf_equals_the_c_library():
    """The sigmoid kernel's vectorised expf repeats glibc's algorithm; checked here against the
    C library's expf on a sample of every float bit pattern plus the edge cases."""
    import ctypes
    import platform

    import tasks.fused_loop as fl

    assert fl.loop_available()
    fn = fl._lib.expf_many_check
    fn.restype = None
    fn.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_int64]
    bits = torch.arange(0, 2**32, 4099, dtype=torch.int64)
    bits = torch.where(bits >= 2**31, bits - 2**32, bits).to(torch.int32)
    edge = torch.tensor([float.fromhex("0x1.04845ep+5"), float.fromhex("-0x1.f8cbb2p+5"), 88.0, -88.0, 87.99, -87.99, 0.0, -0.0, 1e-40,
                         float("inf"), float("-inf"), float("nan"), 100.0, -104.0, -110.0])
    x = torch.cat([bits.view(torch.float32), edge]).contiguous()
    ours, libm = torch.empty_like(x), torch.empty_like(x)
    fn(x.data_ptr(), ours.data_ptr(), libm.data_ptr(), x.numel())
    same = ours.view(torch.int32) == libm.view(torch.int32)
    if platform.libc_ver() == ("glibc", "2.36"):  # the version it was checked against, every float
        assert bool(same.all()), x[~same][:5]
    else:  # another C library may round a few values the other way: at most 1 ulp apart
        finite = torch.isfinite(libm)
        assert bool((ours[~finite].view(torch.int32) == libm[~finite].view(torch.int32)).all())
        assert bool(((ours[finite].view(torch.int32) - libm[finite].view(torch.int32)).abs() <= 1).all())
