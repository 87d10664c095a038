"""rsl-rl's PPO update with each mini-batch step replayed from one CUDA graph.

rsl-rl's ``PPO.update`` runs every mini-batch step eagerly: a few hundred small kernel launches for the forward and
backward passes of two 3 x 256 MLPs, gradient clipping and Adam, then four ``.item()`` host syncs for the loss log.
With ManiSkill's PPO settings (8 epochs of 32 mini-batches: 256 steps per iteration) that costs about as much GPU
wall time as collecting the rollout. :class:`CapturedUpdate` computes the same loss, gradients and Adam step, in the
same order, as rsl-rl's update for a feed-forward actor and critic; on CUDA it captures one mini-batch step (advantage
normalisation, both forward passes, the PPO loss, backward, clipping, Adam, the loss sums) into a CUDA graph and
replays it for every mini-batch, the batch gathered by index into fixed buffers before each replay. The losses are
summed on the device and read once per update. ManiSkill's own PPO baseline does the same with ``torch.compile`` and
CUDA graphs.

What it does not cover (refused by :func:`unsupported`, where rsl-rl's own update is kept): recurrent models, RND,
symmetry augmentation, multi-GPU gradient reduction, mixed precision and the KL-adaptive learning rate (which reads
the KL on the host every step).
"""

from __future__ import annotations

import torch

__all__ = ["CapturedUpdate", "unsupported"]

WARMUP_STEPS = 3
"""Eager mini-batch steps on a side stream before the capture: they allocate autograd's and Adam's state (PyTorch's
recipe for capturing a whole training step)."""


def unsupported(alg) -> str | None:
    """Why ``alg`` (an rsl-rl ``PPO``) cannot use :class:`CapturedUpdate`, or ``None``."""
    checks = [
        (alg.actor.is_recurrent or alg.critic.is_recurrent, "a recurrent actor or critic"),
        (alg.rnd is not None, "RND"),
        (alg.symmetry is not None, "symmetry augmentation"),
        (alg.is_multi_gpu, "multi-GPU training"),
        (alg.use_mixed_precision, "mixed precision"),
        (alg.desired_kl is not None and alg.schedule == "adaptive", "the KL-adaptive learning rate"),
        (not isinstance(alg.optimizer, torch.optim.Adam), f"the optimizer {type(alg.optimizer).__name__} (Adam only)"),
    ]
    found = [why for bad, why in checks if bad]
    return ", ".join(found) if found else None


class CapturedUpdate:
    """``alg.update`` for an rsl-rl ``PPO`` ``alg``: the same mini-batch steps as rsl-rl's, replayed from a CUDA graph
    when ``graph`` is true (CUDA only), else run eagerly (the step the graph captures; on the CPU it equals rsl-rl's
    update). Install with ``alg.update = CapturedUpdate(alg)``."""

    def __init__(self, alg, graph: bool = True):
        why = unsupported(alg)
        if why:
            raise ValueError(f"CapturedUpdate: rsl-rl's PPO with {why} is not supported; keep rsl-rl's update")
        device = torch.device(alg.device)
        if graph and device.type != "cuda":
            raise ValueError(f"CapturedUpdate: graph=True needs a CUDA device, the PPO runs on {device}")
        self.alg = alg
        self.graph = graph
        self._cuda_graph = None
        self._batch = None
        self._sums = torch.zeros(3, device=device)
        self._steps_run = 0
        if graph:
            for group in alg.optimizer.param_groups:
                group["capturable"] = True  # Adam's step count on the device: no host read inside the step

    def _gather(self, flat, idx):
        """The mini-batch of ``idx`` into the fixed buffers the captured step reads."""
        if self._batch is None:
            self._batch = {k: v[idx].clone() for k, v in flat.items()}
            return
        for k, v in flat.items():
            if k == "observations":
                for group in v.keys():
                    torch.index_select(v[group], 0, idx, out=self._batch[k][group])
            else:
                torch.index_select(v, 0, idx, out=self._batch[k])

    def _step(self):
        """One mini-batch step of rsl-rl's ``PPO.update`` on the fixed buffers, its losses added to the sums."""
        alg, b = self.alg, self._batch
        advantages = b["advantages"]
        if alg.normalize_advantage_per_mini_batch:
            advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        # rsl-rl's actor(..., stochastic_output=True) without its discarded sample: torch.normal checks its std on
        # the host, which a capture does not allow
        actor = alg.actor
        actor.distribution.update(actor.mlp(actor.get_latent(b["observations"])))
        log_prob = actor.get_output_log_prob(b["actions"])
        values = alg.critic(b["observations"], masks=None, hidden_state=None)
        entropy = actor.output_entropy
        ratio = torch.exp(log_prob - torch.squeeze(b["old_actions_log_prob"]))
        surrogate = -torch.squeeze(advantages) * ratio
        clipped = -torch.squeeze(advantages) * torch.clamp(ratio, 1.0 - alg.clip_param, 1.0 + alg.clip_param)
        surrogate_loss = torch.max(surrogate, clipped).mean()
        if alg.use_clipped_value_loss:
            value_clipped = b["values"] + (values - b["values"]).clamp(-alg.clip_param, alg.clip_param)
            value_loss = torch.max((values - b["returns"]).pow(2), (value_clipped - b["returns"]).pow(2)).mean()
        else:
            value_loss = (b["returns"] - values).pow(2).mean()
        loss = surrogate_loss + alg.value_loss_coef * value_loss - alg.entropy_coef * entropy.mean()
        alg.optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(alg.actor.parameters(), alg.max_grad_norm)
        torch.nn.utils.clip_grad_norm_(alg.critic.parameters(), alg.max_grad_norm)
        alg.optimizer.step()
        actor.distribution.update(actor.distribution.mean.detach())  # let go of this step's autograd graph
        self._sums += torch.stack([value_loss.detach(), surrogate_loss.detach(), entropy.mean().detach()])

    def _run_step(self):
        if not self.graph:
            self._step()
        elif self._cuda_graph is not None:
            self._cuda_graph.replay()
        elif self._steps_run < WARMUP_STEPS:
            side = torch.cuda.Stream(device=self._sums.device)
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                self._step()
            torch.cuda.current_stream().wait_stream(side)
        else:
            self.alg.optimizer.zero_grad(set_to_none=True)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                self._step()
            self._cuda_graph = graph
            graph.replay()  # the capture ran nothing: this is the step itself
        self._steps_run += 1

    def __call__(self) -> dict[str, float]:
        alg = self.alg
        st = alg.storage
        epochs, minibatches = alg.num_learning_epochs, alg.num_mini_batches
        size = st.num_envs * st.num_transitions_per_env // minibatches
        # rsl-rl's mini_batch_generator: one permutation for all epochs, the same draw from the same generator
        indices = torch.randperm(minibatches * size, requires_grad=False, device=st.device)
        flat = {
            "observations": st.observations.flatten(0, 1),
            "actions": st.actions.flatten(0, 1),
            "values": st.values.flatten(0, 1),
            "returns": st.returns.flatten(0, 1),
            "old_actions_log_prob": st.actions_log_prob.flatten(0, 1),
            "advantages": st.advantages.flatten(0, 1),
        }
        self._sums.zero_()
        for _ in range(epochs):
            for i in range(minibatches):
                self._gather(flat, indices[i * size : (i + 1) * size])
                self._run_step()
        obs = flat["observations"]
        for model in (alg.actor, alg.critic):
            norm = getattr(model, "obs_normalizer", None)
            kept = getattr(norm, "_std", None)
            model.update_normalization(obs)
            if isinstance(kept, torch.Tensor) and norm._std is not kept:
                kept.copy_(norm._std)  # rsl-rl rebinds the std; the captured forward reads the first tensor
                norm._std = kept
        value, surrogate, entropy = (self._sums / (epochs * minibatches)).tolist()
        st.clear()
        return {"value": value, "surrogate": surrogate, "entropy": entropy}
