"""The C network kernel and every control-step path of PopulationRecurrentIzhikevich against the torch step."""

import shutil
import subprocess

import pytest
import torch

from snn_torch import PopulationRecurrentIzhikevich
from snn_torch.functional.izhikevich import QIU2019, REGULAR_SPIKING
from snn_torch.functional.recurrent import (
    ordered_synaptic_current,
    recurrent_init,
    recurrent_izhikevich_steps,
)
from snn_torch.kernels.network import kernel_available, network_steps_kernel

needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler on this machine: the torch step is used instead")


def _case(G, B, N, dtype, seed=0, n_src=0):
    g = torch.Generator().manual_seed(seed)
    mask = torch.rand(G, N, N, generator=g) < 0.4
    w = (torch.randn(G, N, N, generator=g) * 16 * mask).to(dtype)
    net = torch.randint(0, G, (B,), generator=g)
    i = (5 + 60 * torch.rand(B, N, generator=g)).to(dtype)
    src = [(torch.rand(B, 20, n_src, generator=g) < 0.3).to(dtype) if n_src else None for _ in range(12)]
    return w, net, i, src


@needs_cc
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("N", [3, 8, 13, 17, 30, 64])  # padded constant sizes, generic sizes, the maximum
@pytest.mark.parametrize("n_src", [0, 2])
def test_kernel_equals_the_torch_steps_bit_for_bit(dtype, N, n_src):
    assert kernel_available()
    w, net, i, src = _case(11, 29, N, dtype, seed=N, n_src=n_src)
    ref = ker = recurrent_init((29, N), QIU2019, dtype=dtype)
    total = 0
    for s in src:  # 12 control steps of 20 substeps: a spike-timing difference would compound
        c_ref, ref = recurrent_izhikevich_steps(i, ref, w[net], QIU2019, substeps=20, source_spikes=s)
        c_ker, ker = network_steps_kernel(i, ker, w, QIU2019, dt_ms=0.5, substeps=20, network=net, source_spikes=s)
        assert torch.equal(c_ref, c_ker)
        total += int(c_ref.sum())
    for a, b in zip(ref, ker, strict=True):
        assert torch.equal(a, b)
    assert total > 500  # the networks really spiked
    if n_src:  # sources hold their v and u
        assert torch.equal(ker.v[:, :n_src], torch.full_like(ker.v[:, :n_src], -65.0))


@needs_cc
def test_row_does_not_depend_on_batch_position_or_threads():
    w, net, i, _ = _case(7, 40, 9, torch.float32, seed=3)
    state = recurrent_init((40, 9), REGULAR_SPIKING)
    counts, new = network_steps_kernel(i, state, w, REGULAR_SPIKING, dt_ms=0.5, substeps=50, network=net)
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        for r in (0, 5, 39):  # first lane, a middle lane, the tail chunk
            one = recurrent_init((1, 9), REGULAR_SPIKING)
            c, s = network_steps_kernel(i[r : r + 1], one, w, REGULAR_SPIKING, dt_ms=0.5, substeps=50,
                                        network=net[r : r + 1])
            assert torch.equal(c[0], counts[r]) and torch.equal(s.v[0], new.v[r])
    finally:
        torch.set_num_threads(threads)


def test_ordered_synaptic_current_ignores_extra_empty_slots():
    g = torch.Generator().manual_seed(0)
    z = (torch.rand(6, 5, generator=g) < 0.5).float()
    w = torch.randn(6, 5, 5, generator=g)
    wide_z = torch.cat([z, torch.zeros(6, 3)], 1)
    wide_w = torch.zeros(6, 8, 8)
    wide_w[:, :5, :5] = w
    assert torch.equal(ordered_synaptic_current(wide_z, wide_w)[:, :5], ordered_synaptic_current(z, w))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_module_paths_agree_and_kick_scales_weights(dtype):
    w, net, i, src = _case(5, 12, 7, dtype, seed=1, n_src=2)
    mask = w != 0
    layers = {b: PopulationRecurrentIzhikevich(w, mask, QIU2019, i_background=4.0, synapse_kick_mv=2.0, backend=b)
              for b in ("auto", "torch")}
    out = {}
    for b, layer in layers.items():
        state, counts = None, []
        for s in src[:4]:
            c, state = layer.control_step(i, state, substeps=20, network=net, source_spikes=s)
            counts.append(c)
        out[b] = (torch.stack(counts), state)
    assert torch.equal(out["auto"][0], out["torch"][0])
    assert all(torch.equal(a, b) for a, b in zip(out["auto"][1], out["torch"][1], strict=True))
    # weight * kick / dt is the current per spike
    assert torch.equal(layers["torch"].effective_weight(), torch.where(mask, w, 0.0) * (2.0 / 0.5))
    if shutil.which("cc") or shutil.which("gcc"):
        assert layers["auto"].path(out["auto"][1]) == "kernel"


def test_control_step_errors_name_the_argument():
    w, net, i, _ = _case(5, 12, 7, torch.float32)
    layer = PopulationRecurrentIzhikevich(w, w != 0)
    with pytest.raises(ValueError, match="network"):
        layer.control_step(i, substeps=2)  # 12 rows for 5 networks, no map
    with pytest.raises(ValueError, match="i_ext"):
        layer.control_step(i[:, :3], substeps=2, network=net)
    with pytest.raises(ValueError, match="substeps"):
        layer.control_step(i, substeps=0, network=net)
    with pytest.raises(ValueError, match="network"):
        layer.control_step(i, substeps=2, network=net.int())
    with pytest.raises(ValueError, match="backend"):
        PopulationRecurrentIzhikevich(w, w != 0, backend="fast")
    for bad in (net + 5, net - 1):  # an index outside the 5 networks: refused, never read out of bounds
        with pytest.raises(ValueError, match=r"network indices must lie in \[0, 5\)"):
            layer.control_step(i, substeps=2, network=bad)
        if kernel_available():
            with pytest.raises(ValueError, match="network indices"):
                network_steps_kernel(i, layer.initial_state(i), layer.effective_weight(), layer.p, dt_ms=0.5,
                                     substeps=2, network=bad)


@pytest.mark.parametrize("B", [3, 150, 9000])  # the cumsum and the loop forms
def test_ordered_matvec_is_a_sequential_float64_sum_in_any_batch(B):
    from snn_torch.functional.decode import ordered_matvec

    g = torch.Generator().manual_seed(B)
    y, w = torch.rand(B, 9, generator=g), torch.randn(B, 9, 9, generator=g)
    acc = torch.zeros(B, 9, dtype=torch.float64)
    for i in range(9):
        acc = acc + (y[:, i : i + 1] * w[:, i]).double()
    out = ordered_matvec(y, w)
    assert torch.equal(out, acc.float())
    assert torch.equal(ordered_matvec(y[:2], w[:2]), out[:2])  # a row alone: the same bits


@needs_cc
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_bernoulli_sources_drawn_in_c_equal_the_torch_draws(dtype):
    from snn_torch.functional.counter_rng import BernoulliSources

    w, net, i, _ = _case(6, 21, 10, dtype, seed=5)
    g = torch.Generator().manual_seed(9)
    prob = torch.rand(21, 3, generator=g, dtype=torch.float64) * 0.5
    keys = torch.randint(-(2**62), 2**62, (21,), generator=g)
    ker = ref = recurrent_init((21, 10), QIU2019, dtype=dtype)
    for step in range(5):
        sources = BernoulliSources(prob, keys, step * 20 * 3)
        c_ker, ker = network_steps_kernel(i, ker, w, QIU2019, dt_ms=0.5, substeps=20, network=net,
                                          source_spikes=sources)
        c_ref, ref = recurrent_izhikevich_steps(i, ref, w[net], QIU2019, substeps=20,
                                                source_spikes=sources.spikes(20, dtype))
        assert torch.equal(c_ker, c_ref)
        assert 0 < int(c_ker[:, :3].sum()) < 21 * 20 * 3  # the sources really fired, not always
    assert all(torch.equal(a, b) for a, b in zip(ker, ref, strict=True))


@needs_cc
def test_bernoulli_draws_in_c_equal_torch_at_the_boundary_of_each_probability():
    # the C kernel compares draws as 53-bit integers against ceil(p 2^53): probabilities set to a
    # draw's own value (u < p false) and one ulp either side, and 0, 1, above 1 and below 0
    from snn_torch.functional.counter_rng import BernoulliSources, uniform01

    rows, n_src, substeps, base = 12, 3, 20, 40
    w, net, i, _ = _case(6, rows, 10, torch.float64, seed=3)
    keys = torch.randint(-(2**62), 2**62, (rows,), generator=torch.Generator().manual_seed(4))
    drawn = uniform01(keys.view(rows, 1), torch.arange(n_src).view(1, n_src) + base + 7 * n_src)  # substep 7's
    variant = (torch.arange(rows) % 3).view(rows, 1)  # the draw, one ulp above, one ulp below
    prob = torch.where(variant == 0, drawn, torch.nextafter(drawn, (variant == 1).to(torch.float64)))
    prob[0] = torch.tensor([0.0, 1.0, 1.5])
    prob[1] = torch.tensor([-0.25, -0.0, 2.0**-53])
    sources = BernoulliSources(prob, keys, base)
    state = recurrent_init((rows, 10), QIU2019, dtype=torch.float64)
    c_ker, _ = network_steps_kernel(i, state, w, QIU2019, dt_ms=0.5, substeps=substeps, network=net,
                                    source_spikes=sources)
    c_ref, _ = recurrent_izhikevich_steps(i, state, w[net], QIU2019, substeps=substeps,
                                          source_spikes=sources.spikes(substeps, torch.float64))
    assert torch.equal(c_ker[:, :n_src], c_ref[:, :n_src])
    assert torch.equal(c_ker, c_ref)
    assert c_ref[0, :n_src].tolist() == [0.0, substeps, substeps]  # never, always, always


def test_sigmoid_twin_refuses_bad_network_indices_and_matches_a_row_alone():
    from snn_torch.modules.recurrent import PopulationRecurrentSigmoid

    w, net, _, _ = _case(5, 12, 7, torch.float32)
    layer = PopulationRecurrentSigmoid(w, w != 0, num_clamped=2, num_bias=1)
    x = torch.rand(12, 2, generator=torch.Generator().manual_seed(1))
    with pytest.raises(ValueError, match="network indices"):
        layer.control_step(x, network=net + 5)
    y = layer.control_step(x, updates=3, network=net)
    one = layer.control_step(x[4:5], updates=3, network=net[4:5])
    assert torch.equal(one[0], y[4])
    assert torch.equal(y[:, :2], x) and bool((y[:, 2] == 1).all())  # inputs and bias clamped


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("N, clamped, bias", [(5, 2, 1), (9, 4, 0), (40, 3, 2)])
def test_sigmoid_kernel_equals_the_torch_updates_bit_for_bit(dtype, N, clamped, bias):
    from snn_torch.kernels.sigmoid import sigmoid_kernel_supports
    from snn_torch.modules.recurrent import PopulationRecurrentSigmoid

    g = torch.Generator().manual_seed(N)
    w = (torch.randn(6, N, N, generator=g) * 2).to(dtype)
    mask = torch.rand(6, N, N, generator=g) < 0.6
    net = torch.randint(0, 6, (25,), generator=g)
    x = torch.rand(4, 25, clamped, generator=g, dtype=dtype)
    kernel = PopulationRecurrentSigmoid(w, mask, num_clamped=clamped, num_bias=bias, backend="kernel")
    reference = PopulationRecurrentSigmoid(w, mask, num_clamped=clamped, num_bias=bias, backend="torch")
    assert sigmoid_kernel_supports(kernel.initial_state(25))
    y_k = y_t = None
    for t in range(4):  # state carried across control steps, 2 updates each
        y_k = kernel.control_step(x[t], y_k, updates=2, network=net)
        y_t = reference.control_step(x[t], y_t, updates=2, network=net)
        assert torch.equal(y_k, y_t)
    assert 0.05 < float(y_k[:, clamped + bias:].std())  # the hidden and output values vary
    with pytest.raises(ValueError, match="backend='kernel' needs"):
        kernel.control_step(x[0].to(torch.float16), torch.zeros(25, N, dtype=torch.float16), network=net)


@pytest.mark.skipif(shutil.which("nm") is None, reason="no nm to list a library's symbols")
@pytest.mark.parametrize("stem", ["recurrent_izhikevich", "recurrent_sigmoid", "episodes"])
def test_kernel_libraries_export_exactly_what_their_headers_declare(stem):
    from evolution.kernels import episodes
    from snn_torch.kernels import network as network_kernel
    from snn_torch.kernels import sigmoid as sigmoid_kernel
    from snn_torch.kernels.build import parse_prototypes

    loader, csrc = {"recurrent_izhikevich": (network_kernel._library, network_kernel._CSRC),
                    "recurrent_sigmoid": (sigmoid_kernel._library, sigmoid_kernel._CSRC),
                    "episodes": (episodes._library, episodes._CSRC)}[stem]
    lib = loader()
    if lib is None:
        pytest.skip("no C compiler: kernels unavailable")
    out = subprocess.run(["nm", "-D", "--defined-only", str(lib.path)], capture_output=True, text=True,
                         check=True).stdout
    exported = {line.split()[-1] for line in out.splitlines() if line.split()[1:2] == ["T"]}
    header = csrc / f"{stem}.h"
    assert exported == set(parse_prototypes(header.read_text()))
