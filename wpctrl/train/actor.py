"""The deterministic actor of a ManiSkill-task checkpoint, rebuilt in plain torch: what ``wpctrl export`` writes,
without rsl-rl.

A checkpoint's ``infos["actor"]`` records the configuration rsl-rl's ``MLPModel`` was built from, and its
``actor_state_dict`` that model's weights. :func:`build_actor` makes the same network from them:

- the observation normaliser (``obs_normalization``): rsl-rl's ``EmpiricalNormalization``, which maps ``x`` to
  ``(x - mean) / (std + 0.01)`` with its running statistics (buffers ``_mean``, ``_var``, ``_std`` of shape
  ``(1, obs_dim)`` and the sample ``count``); without it the observations pass unchanged;
- the MLP (``hidden_dims``, ``activation``): ``Linear`` layers, each hidden one followed by the activation, at the
  indices rsl-rl's ``MLP`` gives them (``mlp.0``, ``mlp.2``, ...); a hidden width of -1 is the observation width;
- the deterministic output of the distribution (``distribution_cfg``): for rsl-rl's ``GaussianDistribution``, the
  one `wpctrl train` uses, the Gaussian's mean, which is the MLP's output itself. Its standard deviation parameter is
  checked and left out (a deterministic policy does not use it).

Anything else (another model class, distribution or activation, a weight missing, left over or of another shape) is
an :class:`ExportError` naming the checkpoint and the field.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["ACTIVATIONS", "ExportError", "ObservationNormalizer", "PolicyActor", "build_actor"]


class ExportError(ValueError):
    """A run folder or checkpoint that cannot be exported (the message names what and why)."""


ACTIVATIONS = {
    "elu": nn.ELU,
    "selu": nn.SELU,
    "relu": nn.ReLU,
    "crelu": nn.CELU,
    "lrelu": nn.LeakyReLU,
    "tanh": nn.Tanh,
    "sigmoid": nn.Sigmoid,
    "softplus": nn.Softplus,
    "gelu": nn.GELU,
    "swish": nn.SiLU,
    "mish": nn.Mish,
    "identity": nn.Identity,
}
"""rsl-rl's activation names (matched without regard to case) and the torch modules they stand for, with torch's
default parameters."""

NORMALIZER_EPS = 1e-2
"""Added to the normaliser's standard deviation before dividing (rsl-rl's ``EmpiricalNormalization`` default)."""

MODEL_DEFAULTS = {"class_name": "MLPModel", "hidden_dims": [256, 256, 256], "activation": "elu",
                  "obs_normalization": False, "distribution_cfg": None}  # fmt: skip
"""The actor configuration's fields and rsl-rl's ``MLPModel`` defaults for those a checkpoint leaves out."""

GAUSSIAN_FIELDS = ("class_name", "init_std", "std_range", "std_type", "learn_std")
"""The fields of rsl-rl's ``GaussianDistribution`` configuration."""
STD_PARAMETERS = {"scalar": "distribution.std_param", "log": "distribution.log_std_param"}
"""The Gaussian's standard deviation parameter in the state dict, by ``std_type`` (default ``"scalar"``)."""


class ObservationNormalizer(nn.Module):
    """rsl-rl's running observation normaliser as the policy applies it: ``(obs - mean) / (std + eps)``."""

    def __init__(self, obs_dim: int, eps: float = NORMALIZER_EPS):
        super().__init__()
        self.eps = eps
        self.register_buffer("_mean", torch.zeros(1, obs_dim))
        self.register_buffer("_var", torch.ones(1, obs_dim))
        self.register_buffer("_std", torch.ones(1, obs_dim))
        self.register_buffer("count", torch.tensor(0, dtype=torch.long))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - self._mean) / (self._std + self.eps)


class HiddenInputs(nn.Module):
    """Zeros in the observation columns the policy was trained without (:mod:`wpctrl.train.hidden_inputs`)."""

    def __init__(self, obs_dim: int, columns):
        super().__init__()
        keep = torch.ones(1, obs_dim, dtype=torch.bool)
        keep[0, list(columns)] = False
        self.register_buffer("keep", keep)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return torch.where(self.keep, obs, torch.zeros_like(obs))


class PolicyActor(nn.Module):
    """Observation ``(batch, obs_dim)`` -> deterministic action ``(batch, num_actions)``: the hidden columns zeroed
    (:meth:`hide_inputs`; none by default), the normaliser (or none), then the MLP, whose output is the Gaussian's
    mean. Its state dict has the keys of rsl-rl's ``MLPModel`` less the distribution's (and the hidden columns' mask,
    once set)."""

    def __init__(self, obs_dim: int, num_actions: int, hidden_dims, activation: str = "elu",
                 obs_normalization: bool = False):  # fmt: skip
        super().__init__()
        self.obs_dim = obs_dim
        self.num_actions = num_actions
        self.obs_normalizer = ObservationNormalizer(obs_dim) if obs_normalization else nn.Identity()
        widths = [obs_dim] + [obs_dim if w == -1 else w for w in hidden_dims]
        layers: list[nn.Module] = []
        for n_in, n_out in zip(widths[:-1], widths[1:]):
            layers += [nn.Linear(n_in, n_out), ACTIVATIONS[activation.lower()]()]
        layers.append(nn.Linear(widths[-1], num_actions))
        self.mlp = nn.Sequential(*layers)
        self.hidden_inputs: nn.Module = nn.Identity()

    def hide_inputs(self, columns) -> PolicyActor:
        """Zero the observation columns ``columns`` before the normaliser (the policy was trained with zeros there)."""
        columns = [int(c) for c in columns]
        bad = [c for c in columns if not 0 <= c < self.obs_dim]
        if bad:
            raise ExportError(f"hidden_obs: expected columns in [0, {self.obs_dim}), got {bad}")
        self.hidden_inputs = HiddenInputs(self.obs_dim, columns) if columns else nn.Identity()
        return self

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.mlp(self.obs_normalizer(self.hidden_inputs(obs)))

    def observation_statistics(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The normaliser's running mean and standard deviation, each ``(obs_dim,)``; zeros and ones without one."""
        if isinstance(self.obs_normalizer, ObservationNormalizer):
            return self.obs_normalizer._mean[0].clone(), self.obs_normalizer._std[0].clone()
        return torch.zeros(self.obs_dim), torch.ones(self.obs_dim)


def _is_rsl_rl_class(name, cls: str) -> bool:
    """Whether ``name`` names rsl-rl's class ``cls``: the bare name, or qualified with an ``rsl_rl`` module."""
    if not isinstance(name, str):
        return False
    module, _, last = name.replace(":", ".").rpartition(".")
    return last == cls and (module == "" or module == "rsl_rl" or module.startswith("rsl_rl."))


def _model_config(cfg, refuse) -> dict:
    """The actor configuration with rsl-rl's defaults filled in, each field checked (``refuse(field, why)``)."""
    if not isinstance(cfg, dict):
        refuse("actor", f"expected the actor's configuration (a dict), got {type(cfg).__name__}")
    for key in cfg:
        if key not in MODEL_DEFAULTS:
            refuse(f"actor.{key}", f"not a field of rsl-rl's MLPModel (expected {', '.join(MODEL_DEFAULTS)})")
    c = {**MODEL_DEFAULTS, **cfg}
    if not _is_rsl_rl_class(c["class_name"], "MLPModel"):
        refuse("actor.class_name", f"{c['class_name']!r}: export rebuilds rsl-rl's MLPModel only")
    dims = c["hidden_dims"]
    widths = isinstance(dims, list | tuple) and len(dims) > 0
    if not widths or not all(type(w) is int and (w > 0 or w == -1) for w in dims):
        refuse("actor.hidden_dims", f"expected a non-empty list of layer widths (positive, or -1), got {dims!r}")
    if not isinstance(c["activation"], str) or c["activation"].lower() not in ACTIVATIONS:
        refuse("actor.activation", f"{c['activation']!r} is not one of rsl-rl's activations ({', '.join(ACTIVATIONS)})")
    if not isinstance(c["obs_normalization"], bool):
        refuse("actor.obs_normalization", f"expected true or false, got {c['obs_normalization']!r}")
    dist = c["distribution_cfg"]
    name = dist.get("class_name") if isinstance(dist, dict) else None
    if not _is_rsl_rl_class(name, "GaussianDistribution"):
        got = repr(name) if isinstance(dist, dict) else f"{dist!r}"
        refuse("actor.distribution_cfg", f"{got}: export supports rsl-rl's GaussianDistribution only (the "
                                          "distribution `wpctrl train` uses)")  # fmt: skip
    for key in dist:
        if key not in GAUSSIAN_FIELDS:
            fields = ", ".join(GAUSSIAN_FIELDS)
            refuse(f"actor.distribution_cfg.{key}", f"not a field of rsl-rl's GaussianDistribution ({fields})")
    if dist.get("std_type", "scalar") not in STD_PARAMETERS:
        refuse("actor.distribution_cfg.std_type", f"expected 'scalar' or 'log', got {dist['std_type']!r}")
    return c


def build_actor(cfg, obs_dim: int, num_actions: int, state_dict, source) -> PolicyActor:
    """The deterministic actor of the configuration ``cfg`` (a checkpoint's ``infos["actor"]``) with the weights
    ``state_dict`` (its ``actor_state_dict``), in eval mode. ``source`` (the checkpoint) prefixes every refusal."""

    def refuse(field: str, why: str):
        raise ExportError(f"{source}: {field}: {why}")

    c = _model_config(cfg, refuse)
    actor = PolicyActor(obs_dim, num_actions, list(c["hidden_dims"]), c["activation"], c["obs_normalization"])
    std_key = STD_PARAMETERS[c["distribution_cfg"].get("std_type", "scalar")]
    expected = {k: tuple(v.shape) for k, v in actor.state_dict().items()} | {std_key: (num_actions,)}
    if not isinstance(state_dict, dict):
        refuse("actor_state_dict", f"expected the actor's weights (a dict), got {type(state_dict).__name__}")
    missing = [k for k in expected if k not in state_dict]
    extra = [k for k in state_dict if k not in expected]
    if missing or extra:
        what = [f"missing {', '.join(missing)}"] * bool(missing) + [f"unexpected {', '.join(extra)}"] * bool(extra)
        refuse("actor_state_dict", f"does not match the recorded actor ({_describe(c)}): {'; '.join(what)}")
    shapes = {k: tuple(getattr(state_dict[k], "shape", ())) for k in expected}
    wrong = [f"{k} is {shapes[k]}, the record makes {shape}" for k, shape in expected.items() if shapes[k] != shape]
    if wrong:
        refuse("actor_state_dict", f"the weights do not fit the recorded sizes (observations {obs_dim}, actions "
                                   f"{num_actions}, hidden {list(c['hidden_dims'])}): {'; '.join(wrong)}")  # fmt: skip
    try:
        actor.load_state_dict({k: v for k, v in state_dict.items() if k != std_key}, strict=True)
    except (RuntimeError, TypeError, AttributeError) as e:  # a value that is not a tensor
        refuse("actor_state_dict", f"the weights do not load ({type(e).__name__}: {e})")
    return actor.eval()


def _describe(c: dict) -> str:
    norm = "with" if c["obs_normalization"] else "without"
    return f"hidden {list(c['hidden_dims'])}, {c['activation']}, {norm} observation normaliser"
