"""The actuator LSTM the network tests feed to ``wpctrl.ActuatorNet``: legged_gym / Isaac Lab's layout, torques,
(h, c) = net(x, (h, c)) on x of shape (batch, 1, 2)."""

from __future__ import annotations

import torch


class LSTMNet(torch.nn.Module):
    def __init__(self, hidden: int, layers: int):
        super().__init__()
        self.lstm = torch.nn.LSTM(2, hidden, layers, batch_first=True)
        self.linear = torch.nn.Linear(hidden, 1)

    def forward(self, x, hc: tuple[torch.Tensor, torch.Tensor]):
        out, (h, c) = self.lstm(x, hc)
        return self.linear(out), (h, c)
