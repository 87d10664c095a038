"""The rollout's sync-free action sampling (``wpctrl.train.sampling``) against rsl-rl's ``PPO.act``: from the same
random state on the CPU, the same transition (actions, values, log-probabilities, distribution parameters) and, over
a rollout of PushCube envs, the same storage; what it refuses. On CUDA: a rollout with no host sync."""

from __future__ import annotations

import contextlib
import copy
import io

import pytest

pytest.importorskip("rsl_rl", reason="the train extra (rsl-rl-lib) is not installed")  # a dev dependency
torch = pytest.importorskip("torch", reason="torch is not installed")  # a dev dependency

from wpctrl.train.sampling import act, sync_free  # noqa: E402
from wpctrl.train.task_env import TaskVecEnv  # noqa: E402
from wpctrl.train.task_ppo import Collector, maniskill_ppo_cfg  # noqa: E402

N = 6


def _alg(vec, obs_normalization=False, distribution=None):
    from rsl_rl.runners import OnPolicyRunner

    cfg = maniskill_ppo_cfg(3, 1, 2, obs_normalization=obs_normalization)
    if distribution:
        cfg["actor"]["distribution_cfg"] = distribution
    torch.manual_seed(0)
    with contextlib.redirect_stdout(io.StringIO()):
        alg = OnPolicyRunner(vec, cfg, log_dir=None, device=str(vec.device)).alg
    if hasattr(alg.actor.distribution, "log_std_param"):  # a std that is not all ones: scaling by it is tested
        with torch.no_grad():
            alg.actor.distribution.log_std_param.copy_(torch.linspace(-1.0, 0.5, vec.num_actions))
    alg.train_mode()
    return alg


@pytest.fixture(scope="module")
def vec():
    return TaskVecEnv("PushCube-v1", N, seed=2, substeps=2)


def test_act_stores_rsl_rls_transition(vec):
    alg = _alg(vec, obs_normalization=True)
    obs = vec.get_observations()
    torch.manual_seed(11)
    ref_actions = alg.act(obs).clone()
    ref = {k: getattr(alg.transition, k) for k in ("values", "actions_log_prob")}
    ref_params = alg.transition.distribution_params
    alg.transition.clear()
    torch.manual_seed(11)
    actions = act(alg, obs)
    t = alg.transition
    assert not torch.equal(actions, alg.actor(obs))  # sampled: not the mean
    torch.testing.assert_close(actions, ref_actions, rtol=0, atol=0)
    torch.testing.assert_close(t.actions, ref_actions, rtol=0, atol=0)
    for k, v in ref.items():
        torch.testing.assert_close(getattr(t, k), v, rtol=0, atol=0, msg=k)
    assert len(t.distribution_params) == len(ref_params) == 2
    for ours, theirs in zip(t.distribution_params, ref_params):
        torch.testing.assert_close(ours, theirs, rtol=0, atol=0)
    assert t.observations is obs and t.hidden_states == (None, None)


def test_rollout_fills_the_storage_as_rsl_rls_sampling_does(vec):
    ref_alg = _alg(vec)
    ours_alg = copy.deepcopy(ref_alg)
    stores = []
    for alg, sampling in ((ref_alg, "rsl-rl"), (ours_alg, "sync-free")):
        vec = TaskVecEnv("PushCube-v1", N, seed=4, substeps=2)  # fresh: MuJoCo warm-starts from its last step
        torch.manual_seed(5)
        with torch.inference_mode():
            Collector(vec, alg, sampling).rollout(vec.get_observations(), 3)
        st = alg.storage
        stores.append({"obs": st.observations["policy"].clone(), "actions": st.actions.clone(),
                       "rewards": st.rewards.clone(), "values": st.values.clone(),
                       "log_prob": st.actions_log_prob.clone(), "mean": st.distribution_params[0].clone()})  # fmt: skip
    assert stores[0]["actions"].std() > 0.1
    for k in stores[0]:
        torch.testing.assert_close(stores[1][k], stores[0][k], rtol=0, atol=0, msg=k)


def test_sync_free_sampling_is_refused_for_other_distributions(vec):
    hetero = _alg(vec, distribution={"class_name": "HeteroscedasticGaussianDistribution", "init_std": 1.0})
    assert "HeteroscedasticGaussianDistribution" in sync_free(hetero)
    with pytest.raises(ValueError, match="sync-free sampling does not support the distribution "
                                         "HeteroscedasticGaussianDistribution"):  # fmt: skip
        Collector(vec, hetero, "sync-free")
    with pytest.raises(ValueError, match="sampling expected one of"):
        Collector(vec, _alg(vec), "normal")
    Collector(vec, hetero, "rsl-rl")  # rsl-rl's own act takes any distribution


def test_sync_free_rollout_never_calls_torch_normal(vec, monkeypatch):
    """The call that syncs on CUDA (``torch.normal`` with a std tensor) is not made by a sync-free rollout; rsl-rl's
    sampling makes it (checked on the CPU, where the sync itself does not exist)."""
    alg = _alg(vec)

    def refuse(*args, **kwargs):
        raise AssertionError("torch.normal called")

    monkeypatch.setattr(torch, "normal", refuse)
    with torch.inference_mode():
        Collector(vec, alg, "sync-free").rollout(vec.get_observations(), 2)
        alg.storage.clear()
        with pytest.raises(AssertionError, match="torch.normal called"):
            Collector(vec, alg, "rsl-rl").rollout(vec.get_observations(), 1)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA: the host sync is a CUDA stream's")
def test_a_cuda_rollout_does_not_wait_for_the_gpu():
    """With sync-free sampling a rollout raises no error under torch's sync debug mode set to "error" (any
    host-device sync raises); rsl-rl's sampling does (torch.normal checks its std on the host)."""
    cuda = TaskVecEnv("PushCube-v1", 64, device="cuda:0", seed=2, substeps=2)
    for sampling, syncs in (("sync-free", False), ("rsl-rl", True)):
        alg = _alg(cuda)
        collector = Collector(cuda, alg, sampling)
        obs = cuda.get_observations()
        with torch.inference_mode():
            collector.rollout(obs, 1)  # first call: lazy allocations outside the check
            alg.storage.clear()
            torch.cuda.synchronize()
            torch.cuda.set_sync_debug_mode("error")
            try:
                if syncs:
                    with pytest.raises(RuntimeError, match="synchroniz"):
                        collector.rollout(obs, 1)
                else:
                    collector.rollout(obs, 2)
            finally:
                torch.cuda.set_sync_debug_mode("default")
