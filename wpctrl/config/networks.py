"""Reading an actuator network's weights from TorchScript (or a torch module) into flat float32 arrays. Host only;
torch is imported here, only when an :class:`~wpctrl.config.actuator_models.ActuatorNet` is built.

Supported structures, in the order the module registers its layers (the order ``named_modules`` lists them, which is
the forward order of an ``nn.Sequential`` and of the usual ``lstm`` + ``linear`` actuator modules):

- MLP: ``Linear`` layers, each optionally followed by one elementwise activation (ReLU, ELU, Tanh, Sigmoid, Softsign,
  LeakyReLU, Identity); the input has ``2 * len(input_idx)`` features and the last layer one output.
- LSTM: one ``nn.LSTM`` (``input_size`` 2, any ``num_layers`` and ``hidden_size``, biases on) followed by such a
  head. It is evaluated one substep at a time with the per-env, per-joint hidden and cell state.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from .errors import ConfigError

# Activation codes of the network kernel (wpctrl.kernels.actuator_net).
_ACTIVATIONS = {"Identity": 0, "ReLU": 1, "ELU": 2, "Tanh": 3, "Sigmoid": 4, "Softsign": 5, "LeakyReLU": 6}


@dataclass
class NetworkWeights:
    """A network as the kernel reads it: ``dense`` = (in, out, activation code, parameter, weight offset, bias offset)
    per Linear layer, ``lstm`` = (in, hidden, W_ih, W_hh, b_ih, b_hh offsets) per LSTM layer, ``weights`` flat."""

    kind: str
    dense: tuple
    lstm: tuple
    weights: np.ndarray


def _load(network):
    import torch

    if isinstance(network, (str, os.PathLike)):
        try:
            with warnings.catch_warnings():  # TorchScript is what Isaac Lab's actuator nets ship as
                warnings.simplefilter("ignore", DeprecationWarning)
                return torch.jit.load(os.fspath(network), map_location="cpu")
        except (RuntimeError, ValueError, OSError) as e:
            raise ConfigError(f"actuator.network: cannot load TorchScript from {os.fspath(network)!r}: {e}") from e
    if isinstance(network, torch.nn.Module):
        return network
    raise ConfigError(
        f"actuator.network: expected a TorchScript path or a torch.nn.Module, got {type(network).__name__}"
    )


def _type_name(m) -> str:
    return getattr(m, "original_name", None) or type(m).__name__


def read_network(spec) -> NetworkWeights:
    """The weights and structure of ``spec.network`` (an :class:`~wpctrl.config.actuator_models.ActuatorNet`)."""
    module = _load(spec.network)
    leaves = [m for _, m in module.named_modules() if not list(m.children())]
    flat: list[np.ndarray] = []
    offset = 0

    def put(t) -> int:
        nonlocal offset
        a = t.detach().cpu().numpy().astype(np.float32).reshape(-1)
        flat.append(a)
        start = offset
        offset += a.size
        return start

    dense: list[tuple] = []
    lstm: list[tuple] = []
    for m in leaves:
        name = _type_name(m)
        if name == "LSTM":
            if dense or lstm:
                raise ConfigError("actuator.network: the LSTM must come first, followed by Linear / activation layers")
            sd = m.state_dict()
            layers = len([k for k in sd if k.startswith("weight_ih_l")])
            hidden = int(sd["weight_hh_l0"].shape[1])
            for li in range(layers):
                if f"bias_ih_l{li}" not in sd:
                    raise ConfigError("actuator.network: an LSTM without biases is not supported")
                w_ih, w_hh = sd[f"weight_ih_l{li}"], sd[f"weight_hh_l{li}"]
                if w_ih.shape[0] != 4 * hidden or f"weight_hr_l{li}" in sd:
                    raise ConfigError("actuator.network: projected LSTMs (proj_size) are not supported")
                n_in = int(w_ih.shape[1])
                if li == 0 and n_in != 2:
                    raise ConfigError(f"actuator.network: the LSTM takes [position error, velocity]: input_size 2, "
                                      f"got {n_in}")  # fmt: skip
                lstm.append((n_in, hidden, put(w_ih), put(w_hh), put(sd[f"bias_ih_l{li}"]), put(sd[f"bias_hh_l{li}"])))
        elif name == "Linear":
            sd = m.state_dict()
            w = sd["weight"]
            b = sd.get("bias")
            if b is None:
                import torch

                b = torch.zeros(w.shape[0])
            dense.append([int(w.shape[1]), int(w.shape[0]), 0, 0.0, put(w), put(b)])
        elif name in _ACTIVATIONS:
            if not dense or dense[-1][2] != 0:
                raise ConfigError(f"actuator.network: activation {name} must follow a Linear layer")
            param = 0.0
            if name == "ELU":
                param = float(getattr(m, "alpha", 1.0))
            elif name == "LeakyReLU":
                param = float(getattr(m, "negative_slope", 0.01))
            dense[-1][2], dense[-1][3] = _ACTIVATIONS[name], param
        elif name == "Dropout":
            continue
        else:
            raise ConfigError(
                f"actuator.network: layer {name} is not supported (Linear, LSTM and {sorted(_ACTIVATIONS)} are)"
            )
    if not dense:
        raise ConfigError("actuator.network: expected at least one Linear layer (the output)")
    if dense[-1][1] != 1:
        raise ConfigError(
            f"actuator.network: the last Linear layer must have 1 output (the effort), got {dense[-1][1]}"
        )
    kind = "lstm" if lstm else "mlp"
    if spec.kind != "auto" and spec.kind != kind:
        raise ConfigError(f"actuator.kind: {spec.kind!r}, but the network is an {kind.upper()}")
    n_in = 2 if lstm else 2 * len(spec.input_idx)
    first_in = lstm[-1][1] if lstm else n_in
    if dense[0][0] != first_in:
        what = "the LSTM's hidden size" if lstm else f"2 x len(input_idx) = {n_in}"
        raise ConfigError(f"actuator.network: the first Linear layer takes {dense[0][0]} inputs, expected {what}")
    for a, b in zip(dense, dense[1:]):
        if b[0] != a[1]:
            raise ConfigError(f"actuator.network: Linear layers do not chain ({a[1]} outputs into {b[0]} inputs)")
    weights = np.concatenate(flat) if flat else np.zeros(1, np.float32)
    return NetworkWeights(kind, tuple(tuple(d) for d in dense), tuple(lstm), weights)
