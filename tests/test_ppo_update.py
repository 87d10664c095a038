"""The PPO update that replays each mini-batch step from a CUDA graph (``wpctrl.train.ppo_update``) against rsl-rl's
own ``PPO.update`` on the same rollout of PushCube-v1 envs: the same parameters, optimizer state, observation
normaliser and loss log after the update (run eagerly on the CPU; captured against eager on CUDA), and what it
refuses."""

from __future__ import annotations

import contextlib
import copy
import io

import pytest

pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")  # a dev dependency
torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.ppo_update import CapturedUpdate, unsupported  # noqa: E402
from wpctrl.train.task_env import TaskVecEnv  # noqa: E402
from wpctrl.train.task_ppo import Collector, maniskill_ppo_cfg  # noqa: E402

N = 8


def _alg_after_rollout(
    device: str, clipped_value: bool, steps: int = 3, epochs: int = 2, minibatches: int = 4, max_grad_norm: float = 0.5
):
    """An rsl-rl PPO with ManiSkill's settings whose storage holds a real rollout of ``N`` PushCube envs."""
    from rsl_rl.runners import OnPolicyRunner

    vec = TaskVecEnv("PushCube-v1", N, device=device, seed=5, substeps=2)
    cfg = maniskill_ppo_cfg(steps, epochs, minibatches, obs_normalization=True)  # the normaliser the step refreshes
    cfg["algorithm"]["use_clipped_value_loss"] = clipped_value
    cfg["algorithm"]["max_grad_norm"] = max_grad_norm
    torch.manual_seed(0)
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(vec, cfg, log_dir=None, device=device)
    alg = runner.alg
    alg.train_mode()
    with torch.inference_mode():
        obs = Collector(vec, alg).rollout(vec.get_observations(), steps)
        alg.compute_returns(obs)
    return alg


def _state(alg) -> dict:
    out = {f"actor.{k}": v.detach().clone() for k, v in alg.actor.state_dict().items()}
    out.update({f"critic.{k}": v.detach().clone() for k, v in alg.critic.state_dict().items()})
    for i, s in enumerate(alg.optimizer.state.values()):
        out.update({f"adam{i}.{k}": torch.as_tensor(v).detach().clone().cpu() for k, v in s.items()})
    return out


def _assert_same(a: dict, b: dict, atol: float):
    assert a.keys() == b.keys()
    for k in a:
        torch.testing.assert_close(a[k].cpu().float(), b[k].cpu().float(), atol=atol, rtol=0.0, msg=k)


@pytest.mark.parametrize("clipped_value, max_grad_norm", [(False, 0.5), (True, 1e-3)])
def test_eager_update_is_rsl_rls_on_the_cpu(clipped_value, max_grad_norm):
    """Two copies of the same PPO after the same rollout: rsl-rl's update and the captured update's step run eagerly,
    from the same random state, give the same actor, critic, normaliser and Adam state, and the same mean losses
    (with ManiSkill's gradient-norm bound, and with one small enough that both networks' gradients are clipped)."""
    ref = _alg_after_rollout("cpu", clipped_value, max_grad_norm=max_grad_norm)
    ours = copy.deepcopy(ref)
    before = _state(ref)
    torch.manual_seed(3)
    ref_losses = ref.update()
    torch.manual_seed(3)
    our_losses = CapturedUpdate(ours, graph=False)()
    after = _state(ref)
    moved = [k for k in before if k.startswith("actor.mlp") and not torch.equal(before[k], after[k])]
    assert moved, "the update changed the actor"
    _assert_same(after, _state(ours), atol=1e-6)
    assert ref_losses.keys() == our_losses.keys() == {"value", "surrogate", "entropy"}
    for k in ref_losses:
        assert our_losses[k] == pytest.approx(ref_losses[k], rel=1e-5, abs=1e-7), k
    assert ref.storage.step == ours.storage.step == 0  # both cleared


def test_refuses_what_it_does_not_cover():
    alg = _alg_after_rollout("cpu", False, steps=2, epochs=1, minibatches=1)
    with pytest.raises(ValueError, match="needs a CUDA device, the PPO runs on cpu"):
        CapturedUpdate(alg, graph=True)
    alg.desired_kl, alg.schedule = 0.01, "adaptive"
    assert unsupported(alg) == "the KL-adaptive learning rate"
    with pytest.raises(ValueError, match="KL-adaptive learning rate is not supported; keep rsl-rl's update"):
        CapturedUpdate(alg, graph=False)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a CUDA device")
def test_captured_update_is_the_eager_one_on_cuda():
    """Three updates (the first warms up and captures, the next replay; the normaliser's std is refreshed in between):
    the graph's parameters and losses equal the eager step's."""
    ref = _alg_after_rollout("cuda:0", False, steps=4, epochs=2, minibatches=4)
    ours = copy.deepcopy(ref)
    eager, graph = CapturedUpdate(ref, graph=False), CapturedUpdate(ours, graph=True)
    for it in range(3):
        torch.manual_seed(it)
        a = eager()
        torch.manual_seed(it)
        b = graph()
        _assert_same(_state(ref), _state(ours), atol=1e-5)
        for k in a:
            assert b[k] == pytest.approx(a[k], rel=1e-4, abs=1e-6), (it, k)
        for alg in (ref, ours):  # refill both storages with the same transitions
            alg.storage.step = alg.storage.num_transitions_per_env
        with torch.inference_mode():
            ours.storage.observations.copy_(ref.storage.observations)
            for name in ("actions", "values", "returns", "actions_log_prob", "advantages"):
                getattr(ours.storage, name).copy_(getattr(ref.storage, name))
