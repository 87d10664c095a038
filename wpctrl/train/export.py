"""``python -m wpctrl export RUN_DIR``: the policy a ManiSkill-task run trained (any task of :mod:`wpctrl.tasks`'
registry; its widths are the checkpoint's record), as a self-contained TorchScript
module (``policy.ts``) and, where the ``onnx`` package is importable, an ONNX model (``policy.onnx``).

Both map ManiSkill's flattened ``obs_mode="state"`` observation ``(batch, obs_dim)`` (float32) to the deterministic
action ``(batch, num_actions)`` (the Gaussian's mean; ManiSkill's controllers clip it to the action space): the
columns the run hid zeroed (``hidden_obs``, :mod:`.hidden_inputs`), rsl-rl's running observation normaliser, then
the actor's MLP, both rebuilt from the checkpoint in plain torch
(:mod:`.actor`), so that exporting needs torch alone, not rsl-rl. ``policy.ts`` loads with torch alone
(``torch.jit.load``); its extra file (``EXTRA_FILE``) (and ``policy.json`` beside it, and the ONNX model's metadata)
name the task, control mode, observation layout and action bounds.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import sys
import warnings
from pathlib import Path

import torch

from ..tasks.names import TASK_IDS
from .actor import ExportError, PolicyActor, build_actor
from .command_args import export_parser

__all__ = ["EXTRA_FILE", "ExportError", "TaskPolicy", "export", "load_actor", "main"]

EXTRA_FILE = "wpctrl.json"
"""The TorchScript extra file holding the policy's metadata (``torch.jit.load(path, _extra_files=...)``)."""


class TaskPolicy(torch.nn.Module):
    """The exported policy: ``forward(obs) -> action``; ``task``, ``control_mode``, ``obs_dim``, ``num_actions`` as
    attributes. A wrong observation width raises an error naming both widths."""

    def __init__(self, actor: torch.nn.Module, task: str, control_mode: str, obs_dim: int, num_actions: int):
        super().__init__()
        self.actor = actor
        self.task = task
        self.control_mode = control_mode
        self.obs_dim = obs_dim
        self.num_actions = num_actions

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if obs.shape[-1] != self.obs_dim:
            raise RuntimeError(
                "policy for " + self.task + ": expected observations of width " + str(self.obs_dim)
                + " (ManiSkill's flattened state), got " + str(obs.shape[-1])
            )  # fmt: skip
        return self.actor(obs)


def load_actor(checkpoint: Path) -> tuple[PolicyActor, dict]:
    """The deterministic actor of a ManiSkill-task checkpoint (:func:`.actor.build_actor`: plain torch, no rsl-rl)
    and its metadata (``policy.pt``'s ``infos``)."""
    try:
        data = torch.load(checkpoint, map_location="cpu", weights_only=False)
    except Exception as e:  # noqa: BLE001  (torch raises several kinds for a file that is not a checkpoint)
        raise ExportError(f"{checkpoint}: not a torch checkpoint ({type(e).__name__}: {e})") from e
    infos = data.get("infos") if isinstance(data, dict) else None
    if not isinstance(infos, dict) or infos.get("format") != "wpctrl-task-policy-1":
        raise ExportError(f"{checkpoint}: not a checkpoint of a ManiSkill-task run (no task record in its infos; "
                          f"export takes runs of `wpctrl train --task {' | '.join(TASK_IDS)}`)")  # fmt: skip
    actor = build_actor(infos.get("actor"), int(infos["obs_dim"]), int(infos["num_actions"]),
                        data.get("actor_state_dict"), checkpoint)  # fmt: skip
    hidden = infos.get("hidden_obs", [])
    if not isinstance(hidden, list) or not all(isinstance(c, int) and not isinstance(c, bool) for c in hidden):
        raise ExportError(f"{checkpoint}: hidden_obs: expected a list of observation columns, got {hidden!r}")
    try:
        actor.hide_inputs(hidden)
    except ExportError as e:
        raise ExportError(f"{checkpoint}: {e}") from e
    return actor, infos


def _metadata(infos: dict) -> dict:
    keys = ("task", "control_mode", "obs_dim", "num_actions", "action_low", "action_high", "obs_fields", "substeps")
    return {
        "format": "wpctrl-exported-policy-1",
        **{k: infos[k] for k in keys},
        **({"max_episode_steps": infos["max_episode_steps"]} if "max_episode_steps" in infos else {}),
        "robot_uids": infos.get("robot_uids", "panda"),  # a checkpoint from before the robot was recorded: panda
        "hidden_obs": list(infos.get("hidden_obs", [])),
        "input": "ManiSkill's flattened obs_mode='state' observation (batch, obs_dim), float32; the columns of "
                 "hidden_obs are not read (the policy zeroes them, as training did)",
        "output": "deterministic action (batch, num_actions); ManiSkill's controller clips it to the action bounds",
    }


def export(run_dir, out_dir=None, onnx: bool = True) -> dict:
    """Write ``policy.ts`` (and ``policy.onnx``) and ``policy.json`` for the run in ``run_dir``; returns the paths
    and the largest difference between the exported modules' actions and the actor's on 1,000 observations
    drawn around the normaliser's statistics."""
    run = Path(run_dir)
    if not run.is_dir():
        raise ExportError(f"run dir {str(run)!r} does not exist")
    ckpt = run / "policy.pt"
    if not ckpt.is_file():
        raise ExportError(f"run dir {str(run)!r} has no policy.pt (the checkpoint `wpctrl train` writes)")
    actor, infos = load_actor(ckpt)
    out = Path(out_dir) if out_dir else run
    out.mkdir(parents=True, exist_ok=True)
    meta = _metadata(infos)
    module = TaskPolicy(actor, infos["task"], infos["control_mode"], int(infos["obs_dim"]),
                        int(infos["num_actions"]))  # fmt: skip
    scripted = torch.jit.script(module.eval())
    ts_path = out / "policy.ts"
    torch.jit.save(scripted, str(ts_path), _extra_files={EXTRA_FILE: json.dumps(meta)})
    (out / "policy.json").write_text(json.dumps(meta, indent=1))
    obs = _probe_observations(actor, 1000)
    with torch.inference_mode():
        reference = actor(obs)
        loaded = torch.jit.load(str(ts_path))
        result = {"policy.ts": str(ts_path), "policy.json": str(out / "policy.json"),
                  "ts_max_abs_diff": float((loaded(obs) - reference).abs().max())}  # fmt: skip
    if onnx:
        result.update(_export_onnx(actor, meta, out / "policy.onnx", obs, reference))
    return result


def _probe_observations(actor: PolicyActor, n: int) -> torch.Tensor:
    """Observations spread as the training data were (the normaliser's mean and std), seeded."""
    g = torch.Generator().manual_seed(0)
    mean, std = actor.observation_statistics()
    return mean + 2.0 * std * torch.randn(n, actor.obs_dim, generator=g)


def _export_onnx(actor: PolicyActor, meta: dict, path: Path, obs, reference) -> dict:
    """ONNX (opset 18, dynamic batch) with the metadata as model properties; checked with ONNX's own reference
    evaluator against the actor."""
    try:
        import onnx
        from onnx.reference import ReferenceEvaluator
    except ImportError:
        return {"onnx": "skipped: the onnx package is not importable (pip install onnx onnxscript)"}
    model = actor.eval()
    example = (torch.zeros(1, int(meta["obs_dim"])),)
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        try:  # torch.export-based exporter (needs onnxscript), else the TorchScript-based one
            torch.onnx.export(model, example, str(path), input_names=["obs"], output_names=["actions"],
                              dynamic_shapes=({0: torch.export.Dim("batch")},), dynamo=True)  # fmt: skip
        except Exception:  # noqa: BLE001
            torch.onnx.export(model, example, str(path), input_names=["obs"], output_names=["actions"],
                              dynamic_axes={"obs": {0: "batch"}, "actions": {0: "batch"}}, opset_version=18,
                              dynamo=False)  # fmt: skip
    m = onnx.load(str(path), load_external_data=True)
    for k, v in meta.items():
        p = m.metadata_props.add()
        p.key, p.value = k, json.dumps(v) if not isinstance(v, str) else v
    onnx.save(m, str(path), save_as_external_data=False)
    Path(f"{path}.data").unlink(missing_ok=True)  # the exporter's external weights, now inside the model
    onnx.checker.check_model(str(path))
    got = ReferenceEvaluator(str(path)).run(None, {"obs": obs.numpy()})[0]
    return {"policy.onnx": str(path), "onnx_max_abs_diff": float(abs(got - reference.numpy()).max())}


TORCH_JIT_DEPRECATION = r"`torch\.jit\.\w+` is deprecated"
"""torch (2.10 and later) marks TorchScript deprecated on every ``torch.jit.script`` / ``save`` / ``load``; the
export writes TorchScript on purpose (it loads with torch alone, and ManiSkill's and Isaac Lab's deployment read
it)."""
TORCHVISION_SKIPPED = "torchvision is not installed. Skipping torchvision::"
"""torch's ONNX exporter logs this once per torchvision operator when torchvision is absent; the policy uses none."""


class _DropTorchvisionNotes(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(TORCHVISION_SKIPPED)


@contextlib.contextmanager
def known_third_party_notes_hidden():
    """Within the block, two notes of torch that do not concern an exported policy are not shown: TorchScript's
    deprecation warnings (:data:`TORCH_JIT_DEPRECATION`) and the ONNX exporter's "torchvision is not installed"
    lines (:data:`TORCHVISION_SKIPPED`). Every other warning and log line still shows; ``--verbose`` shows these
    too."""
    drop = _DropTorchvisionNotes()
    loggers = [logging.getLogger("torch.onnx._internal.exporter._registration")]  # where torch logs them
    with warnings.catch_warnings():
        for category in (DeprecationWarning, FutureWarning):
            warnings.filterwarnings("ignore", message=TORCH_JIT_DEPRECATION, category=category)
        for logger in loggers:
            logger.addFilter(drop)
        try:
            yield
        finally:
            for logger in loggers:
                logger.removeFilter(drop)


def main(argv=None) -> int:
    args = export_parser().parse_args(argv)
    hide = contextlib.nullcontext() if args.verbose else known_third_party_notes_hidden()
    try:
        with hide:
            result = export(args.run_dir, args.out, onnx=not args.no_onnx)
    except (ExportError, ImportError) as e:
        print(f"wpctrl export: error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {result['policy.ts']} (TorchScript; actions within {result['ts_max_abs_diff']:.1e} of the "
          f"checkpoint's actor on 1,000 observations)")  # fmt: skip
    if "policy.onnx" in result:
        print(f"wrote {result['policy.onnx']} (ONNX; within {result['onnx_max_abs_diff']:.1e}, ONNX's reference "
              "evaluator)")  # fmt: skip
    elif "onnx" in result:
        print(f"ONNX {result['onnx']}")
    print(f"wrote {result['policy.json']}")
    return 0
