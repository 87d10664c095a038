"""The actor ``wpctrl export`` rebuilds in plain torch (:mod:`wpctrl.train.actor`): equal to rsl-rl's ``MLPModel``'s
deterministic output (rsl-rl imported here as the independent reference) for every actor configuration the training
makes and every activation rsl-rl names, with and without the observation normaliser; and the checkpoints it refuses,
naming the checkpoint and the field: another distribution, model or activation, a weight missing, left over or of
another size."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.actor import ACTIVATIONS, ExportError, PolicyActor, build_actor  # noqa: E402

OBS, ACTIONS = 35, 8
"""PushCube-v1's observation and action widths."""


def _rsl_rl_actor(cfg: dict, obs_dim: int = OBS, num_actions: int = ACTIONS, seed: int = 0):
    """rsl-rl's ``MLPModel`` of the actor configuration ``cfg``, with random weights and, where it has one, a
    normaliser whose statistics moved away from 0 / 1 (as a trained one's have)."""
    pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")
    from rsl_rl.models import MLPModel
    from tensordict import TensorDict

    torch.manual_seed(seed)
    kwargs = {k: v for k, v in cfg.items() if k != "class_name"}
    model = MLPModel(TensorDict({"policy": torch.zeros(1, obs_dim)}, batch_size=[1]), {"actor": ["policy"]}, "actor",
                     num_actions, **kwargs)  # fmt: skip
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(0.3 * torch.randn_like(p))
    if kwargs.get("obs_normalization"):
        model.train()
        for _ in range(3):
            batch = 1.5 + 4.0 * torch.rand(obs_dim) * torch.randn(64, obs_dim)
            model.update_normalization(TensorDict({"policy": batch}, batch_size=[64]))
    return model.eval()


def _project_actor_configs() -> dict:
    """The actor configurations the training makes: the ManiSkill tasks' (normaliser off and on) and reach's."""
    pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")
    from wpctrl.train.reach_ppo import train_cfg
    from wpctrl.train.task_ppo import maniskill_ppo_cfg

    return {
        "tasks": maniskill_ppo_cfg()["actor"],
        "tasks-normalised": maniskill_ppo_cfg(obs_normalization=True)["actor"],
        "reach": train_cfg()["actor"],
    }


def _assert_same_actions(cfg: dict, obs_dim: int = OBS):
    from tensordict import TensorDict

    reference = _rsl_rl_actor(cfg, obs_dim)
    actor = build_actor(copy.deepcopy(cfg), obs_dim, ACTIONS, reference.state_dict(), "reference.pt")
    obs = 1.5 + 3.0 * torch.randn(500, obs_dim, generator=torch.Generator().manual_seed(1))
    with torch.inference_mode():
        want = reference(TensorDict({"policy": obs}, batch_size=[500]))
        got = actor(obs)
    assert got.shape == (500, ACTIONS) and float(want.abs().max()) > 0.05
    np.testing.assert_allclose(got.numpy(), want.numpy(), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", ["tasks", "tasks-normalised", "reach"])
def test_actor_is_rsl_rls_deterministic_output_for_the_training_configurations(name):
    cfg = _project_actor_configs()[name]
    assert cfg["distribution_cfg"]["class_name"] == "GaussianDistribution"
    _assert_same_actions(cfg)


@pytest.mark.parametrize("normalised", [False, True])
@pytest.mark.parametrize("activation", sorted(ACTIVATIONS))
def test_actor_is_rsl_rls_deterministic_output_for_every_activation(activation, normalised):
    """Each rsl-rl activation name (one in capitals: rsl-rl ignores case), a hidden width of -1 (the observation
    width), both standard deviation parameterisations."""
    std_type = "log" if normalised else "scalar"
    gaussian = {"class_name": "GaussianDistribution", "init_std": 0.5, "std_type": std_type}
    cfg = {"class_name": "MLPModel", "hidden_dims": [24, -1], "activation": activation.upper() if normalised else
           activation, "obs_normalization": normalised, "distribution_cfg": gaussian}  # fmt: skip
    _assert_same_actions(cfg, obs_dim=12)


# -- refusals ----------------------------------------------------------------------------------------------------------

GAUSSIAN = {"class_name": "GaussianDistribution", "init_std": 1.0, "std_type": "log"}
TASK_ACTOR = {"class_name": "MLPModel", "hidden_dims": [32, 32], "activation": "tanh", "obs_normalization": True,
              "distribution_cfg": GAUSSIAN}  # fmt: skip


def _weights(cfg: dict = TASK_ACTOR) -> dict:
    """A state dict as rsl-rl saves the actor of ``cfg`` (PolicyActor's keys and the Gaussian's log-std)."""
    actor = PolicyActor(OBS, ACTIONS, cfg["hidden_dims"], cfg["activation"], cfg["obs_normalization"])
    return {**actor.state_dict(), "distribution.log_std_param": torch.zeros(ACTIONS)}


def _checkpoint(path, actor_cfg=TASK_ACTOR, weights=None, **more):
    """A ManiSkill-task checkpoint as `wpctrl train` writes it (the infos export reads), in ``path``/policy.pt."""
    path.mkdir(parents=True, exist_ok=True)
    bounds = {"action_low": [-1.0] * ACTIONS, "action_high": [1.0] * ACTIONS}
    infos = {"format": "wpctrl-task-policy-1", "task": "PushCube-v1", "control_mode": "pd_joint_delta_pos",
             "obs_dim": OBS, "num_actions": ACTIONS, **bounds, "obs_fields": [["agent", "qpos", 9]], "substeps": 4,
             "partial_reset": True, "actor": actor_cfg, **more}  # fmt: skip
    torch.save({"actor_state_dict": _weights() if weights is None else weights, "infos": infos}, path / "policy.pt")
    return path


def test_export_of_a_checkpoint_writes_the_rebuilt_actor(tmp_path):
    from wpctrl.train.export import EXTRA_FILE, export

    weights = _weights()
    weights["obs_normalizer._mean"] += 2.0
    result = export(_checkpoint(tmp_path / "run", weights=weights), onnx=False)
    assert result["ts_max_abs_diff"] == 0.0 and "policy.onnx" not in result
    extra = {EXTRA_FILE: ""}
    module = torch.jit.load(result["policy.ts"], _extra_files=extra)
    actor = build_actor(TASK_ACTOR, OBS, ACTIONS, weights, "policy.pt")
    obs = torch.randn(7, OBS)
    assert torch.equal(module(obs), actor(obs))
    assert json.loads(extra[EXTRA_FILE])["task"] == "PushCube-v1"


def test_exported_policy_reads_nothing_of_the_hidden_columns(tmp_path):
    """A run that hid columns 16 and 17 (the finger joints' velocities): the TorchScript and ONNX policies are rsl-rl's
    actor (the independent reference) on the observation with those columns zeroed, whatever they hold; the other
    columns still move the action; the metadata names the hidden columns."""
    pytest.importorskip("onnx", reason="the onnx package is not installed")
    from tensordict import TensorDict

    from wpctrl.train.export import EXTRA_FILE, export

    cfg = _project_actor_configs()["tasks"]
    reference = _rsl_rl_actor(cfg, seed=3)
    run = _checkpoint(tmp_path / "run", cfg, {**reference.state_dict()}, hidden_obs=[16, 17])
    result = export(run)
    extra = {EXTRA_FILE: ""}
    module = torch.jit.load(result["policy.ts"], _extra_files=extra)
    assert json.loads(extra[EXTRA_FILE])["hidden_obs"] == [16, 17]
    obs = torch.randn(50, OBS, generator=torch.Generator().manual_seed(2))
    zeroed = obs.clone()
    zeroed[:, 16:18] = 0.0
    with torch.inference_mode():
        want = reference(TensorDict({"policy": zeroed}, batch_size=[50]))
        got = module(obs)
        np.testing.assert_allclose(got.numpy(), want.numpy(), rtol=1e-6, atol=1e-6)
        assert float((module(obs) - reference(TensorDict({"policy": obs}, batch_size=[50]))).abs().max()) > 1e-3
        other = obs.clone()
        other[:, 15] += 1.0
        assert float((module(other) - got).abs().max()) > 1e-3
    from onnx.reference import ReferenceEvaluator

    onnx_out = ReferenceEvaluator(result["policy.onnx"]).run(None, {"obs": obs.numpy()})[0]
    np.testing.assert_allclose(onnx_out, want.numpy(), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("hidden, message", [([35], "hidden_obs: expected columns in [0, 35), got [35]"),
                                             ("16", "hidden_obs: expected a list of observation columns, got '16'"),
                                             ([16.0], "hidden_obs: expected a list of observation columns")])
def test_export_refuses_hidden_columns_outside_the_observation(hidden, message, tmp_path, capsys):
    from wpctrl.train.export import main

    run = _checkpoint(tmp_path / "run", hidden_obs=hidden)
    assert main([str(run)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"wpctrl export: error: {run / 'policy.pt'}: ") and message in err, err
    assert not (run / "policy.ts").exists()


def _without(d: dict, key: str) -> dict:
    return {k: v for k, v in d.items() if k != key}


@pytest.mark.parametrize(
    "actor_cfg, weights, message",
    [
        (dict(TASK_ACTOR, distribution_cfg={"class_name": "BetaDistribution"}),
         None, "actor.distribution_cfg: 'BetaDistribution': export supports rsl-rl's GaussianDistribution only"),
        (dict(TASK_ACTOR, distribution_cfg=dict(GAUSSIAN, class_name="HeteroscedasticGaussianDistribution")),
         None, "actor.distribution_cfg: 'HeteroscedasticGaussianDistribution': export supports"),
        (dict(TASK_ACTOR, distribution_cfg=None), None, "actor.distribution_cfg: None: export supports"),
        (dict(TASK_ACTOR, distribution_cfg=dict(GAUSSIAN, std_type="softplus")),
         None, "actor.distribution_cfg.std_type: expected 'scalar' or 'log', got 'softplus'"),
        (dict(TASK_ACTOR, activation="softsign"), None, "actor.activation: 'softsign' is not one of rsl-rl's"),
        (dict(TASK_ACTOR, class_name="RNNModel"), None, "actor.class_name: 'RNNModel': export rebuilds rsl-rl's"),
        (dict(TASK_ACTOR, rnn_type="lstm"), None, "actor.rnn_type: not a field of rsl-rl's MLPModel"),
        (dict(TASK_ACTOR, hidden_dims=[]), None, "actor.hidden_dims: expected a non-empty list of layer widths"),
        (TASK_ACTOR, _without(_weights(), "mlp.2.weight"), "actor_state_dict: does not match the recorded actor "
         "(hidden [32, 32], tanh, with observation normaliser): missing mlp.2.weight"),
        (TASK_ACTOR, _without(_weights(), "distribution.log_std_param"), "missing distribution.log_std_param"),
        (dict(TASK_ACTOR, obs_normalization=False), None,
         "unexpected obs_normalizer._mean, obs_normalizer._var, obs_normalizer._std, obs_normalizer.count"),
        (dict(TASK_ACTOR, hidden_dims=[32, 64]), None, "actor_state_dict: the weights do not fit the recorded sizes "
         "(observations 35, actions 8, hidden [32, 64]): mlp.2.weight is (32, 32), the record makes (64, 32)"),
    ],
)  # fmt: skip
def test_export_refuses_an_actor_it_cannot_rebuild_naming_checkpoint_and_field(actor_cfg, weights, message, tmp_path,
                                                                               capsys):  # fmt: skip
    from wpctrl.train.export import main

    run = _checkpoint(tmp_path / "run", actor_cfg, weights)
    assert main([str(run)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"wpctrl export: error: {run / 'policy.pt'}: "), err
    assert message in err, err
    assert not (run / "policy.ts").exists()


def test_build_actor_raises_export_error_for_a_state_dict_that_is_not_one():
    with pytest.raises(ExportError, match=r"^ckpt\.pt: actor_state_dict: expected the actor's weights \(a dict\)"):
        build_actor(TASK_ACTOR, OBS, ACTIONS, None, "ckpt.pt")
