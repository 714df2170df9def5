"""The Izhikevich layer inside an ordinary torch model learns by backprop (surrogate gradients)."""

import torch
from torch import nn

from snn_torch import Izhikevich
from snn_torch.functional import firing_rate


class SpikingClassifier(nn.Module):
    """Linear -> Izhikevich neurons for 20 ms -> rates -> Linear."""

    def __init__(self, hidden=32):
        super().__init__()
        self.snn = Izhikevich(2, hidden)
        with torch.no_grad():  # put the neurons' input in their working range (~0-30 nA)
            self.snn.linear.weight.mul_(20.0)
            self.snn.linear.bias.fill_(8.0)
        self.readout = nn.Linear(hidden, 2)

    def forward(self, x, steps=40):
        spikes, _ = self.snn(x.expand(steps, -1, -1))
        return self.readout(firing_rate(spikes, dt_ms=self.snn.dt_ms) / 100.0)


def test_tiny_supervised_task_learns():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    x = torch.rand(256, 2, generator=g) * 2 - 1
    y = ((x[:, 0] * x[:, 1]) > 0).long()  # XOR of the signs: not linearly separable
    model = SpikingClassifier()
    opt = torch.optim.Adam(model.parameters(), lr=0.02)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss = nn.functional.cross_entropy(model(x), y)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] <= 0.5 * losses[0], losses
    with torch.no_grad():
        accuracy = (model(x).argmax(1) == y).float().mean().item()
    assert accuracy > 0.75
    assert model.snn.linear.weight.grad is not None
