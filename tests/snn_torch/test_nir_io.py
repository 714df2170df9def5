"""NIR export and import of LIF / LI / Linear chains round-trip exactly (skipped without nir)."""

import pytest
import torch
from torch import nn

from snn_torch import LI, LIF, Izhikevich, LIFParams, Stateful, reset_states
from snn_torch.modules.nir_io import export_nir, import_nir

nir = pytest.importorskip("nir")


def _model():
    torch.manual_seed(0)
    lif = LIF(4, 6, LIFParams(tau_mem_ms=torch.linspace(5.0, 20.0, 6), v_th=0.8), dt_ms=0.5)
    return nn.Sequential(Stateful(lif), nn.Linear(6, 5, bias=False), Stateful(LI(5, 3, dt_ms=0.5)))


def test_round_trip_through_a_file_gives_the_same_outputs(tmp_path):
    model = _model()
    graph = export_nir(model)
    assert [type(n).__name__ for n in graph.nodes.values()] == ["Input", "Affine", "LIF", "Linear", "Affine", "LI",
                                                                "Output"]
    assert graph.nodes["lif"].tau[0] == pytest.approx(0.005)  # seconds in NIR
    nir.write(tmp_path / "model.nir", graph)
    back = import_nir(nir.read(tmp_path / "model.nir"))
    assert back[0].layer.dt_ms == 0.5
    x = torch.rand(40, 2, 4) * 3
    out, out_back = model(x), back(x)
    assert torch.equal(out, out_back) and out.abs().sum() > 0
    reset_states(model)
    assert (export_nir(back).nodes["lif"].tau == graph.nodes["lif"].tau).all()


def test_unsupported_modules_and_graphs_are_named():
    with pytest.raises(ValueError, match=r"module 0 \(Izhikevich\) has no NIR export"):
        export_nir(nn.Sequential(Izhikevich(2, 3)))
    with pytest.raises(ValueError, match="reset='subtract'"):
        export_nir(LIF(2, 3, reset="subtract"))
    graph = nir.NIRGraph.from_list(nir.Affine(weight=torch.ones(2, 2).numpy(), bias=torch.ones(2).numpy()),
                                   nir.IF(r=torch.ones(2).numpy(), v_threshold=torch.ones(2).numpy()))
    with pytest.raises(ValueError, match="is a IF: supported are"):
        import_nir(graph, dt_ms=1.0)
    with pytest.raises(ValueError, match="pass dt_ms"):
        import_nir(nir.NIRGraph.from_list(nir.Linear(weight=torch.ones(2, 2).numpy())))
