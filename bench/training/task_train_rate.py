"""How fast PPO collects on a ManiSkill task (any of ``wpctrl train``'s: PushCube-v1, PickCube-v1, PullCube-v1, ...),
against the same envs stepped without a policy and the bare MuJoCo-Warp rollout of the same scene.

Every part is the training env's own model, solver, controller and buffers (``wpctrl.train.task_env.TaskVecEnv``
over ``wpctrl.tasks``), each captured in its own graph (CUDA; eager on the CPU) and replayed back to back; µs per
control step (median of ``--repeats`` samples):

* **MuJoCo-Warp rollout**: the control step's 5 x ``substeps`` solver steps alone (the contacts and Newton's contact
  sensor of the last one included, as the env computes them): simulating these envs with no controller, no task
  kernels, no policy;
* **controller calls**: ``set_action`` + 5 x ``before_simulation_step`` alone (the controller's share of the step);
* **env.step without a policy**: the training env's whole step as PPO calls it (action copy, its graph: controller,
  physics, evaluation / observation / reward, episode bookkeeping, auto reset; the returned tensors and episode
  statistics), with a fixed action;
* **rsl-rl alone**: PPO's ``act`` + the critic on the final observations (the bootstrap) + ``process_env_step`` on
  a fixed observation, no env step;
* **PPO collection step**: one step of the training's rollout (``act`` -> ``env.step`` -> bootstrap ->
  ``process_env_step``), back to back. Its rate over the rollout's is the collection efficiency; set against the sum
  and the larger of the env step and rsl-rl alone, it shows whether the policy's work overlaps the env step or adds
  to it;
* **PPO rollout, then a sync**: one iteration's rollout (``--steps-per-env`` steps) and a device sync, as the
  training times its collection (per step).

* **the same states, with and without the policy**: ``--replay-steps`` collection steps from a fixed reset, their
  actions recorded, then the env reset the same way and stepped with the recorded actions alone: the env's cost on
  the states the policy drives it through (an arm in motion costs MuJoCo-Warp's solver more iterations than one at
  rest), and the collection's overhead over exactly that work.

``--action-sampling`` picks the training's sampler (``wpctrl train``'s flag). On CUDA the host's cost of launching each
captured graph is also measured on its own (a sync before every launch, so that a full launch queue cannot stall it):
if the env step's launch takes the host about as long as the GPU takes to run it, nothing can hide it.

With ``--train-json`` (a ``python -m wpctrl train --task ...`` run with the same envs on the same device), that
run's collection rate (median over its iterations after the first) is divided by the rollout's as well.

    python bench/training/task_train_rate.py --task PushCube-v1 --envs 4096 --substeps 8 \
        --train-json runs/push/train.json

Writes ``<out>/task_train_rate_<task>_<cpu|cuda>.{json,md}``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import warp as wp  # noqa: E402

from bench.common import machine_info, md_table, meta_markdown, task_step_parts, write_results  # noqa: E402
from bench.training.train_rate import _host_time, _time, collection_rate  # noqa: E402
from wpctrl.train.ppo_config import task_recipe  # noqa: E402
from wpctrl.train.train_config import MANISKILL_TASKS  # noqa: E402

ROLLOUT = "MuJoCo-Warp rollout (5 x substeps solver steps)"
CONTROLLER = "controller calls"
ENV_STEP = "env.step without a policy"
RSL_RL = "rsl-rl alone (act + bootstrap value + process_env_step)"
COLLECT = "PPO collection step"
ITERATION = "PPO rollout, then a sync (per step)"


def _launch_host_time(graph, sync, repeats: int) -> float:
    """Median host seconds of one ``capture_launch(graph)`` issued with the device idle."""
    samples = []
    for _ in range(repeats):
        sync()
        t = time.perf_counter()
        wp.capture_launch(graph)
        samples.append(time.perf_counter() - t)
    sync()
    return statistics.median(samples)


def _same_states(vec, collector, alg, sync, steps: int) -> dict:
    """Seconds per step of ``steps`` collection steps from ``reset(seed=1)``, their actions recorded, and of the env
    stepped with those actions alone from the same reset (the same states, up to MuJoCo's warm start)."""
    actions = []
    obs = vec.reset(seed=1)
    sync()
    t = time.perf_counter()
    for _ in range(steps):
        if alg.storage.step >= alg.storage.num_transitions_per_env:
            alg.storage.clear()
        obs = collector.rollout(obs, 1)
        actions.append(alg.storage.actions[alg.storage.step - 1].clone())  # the storage wraps: copy now
    sync()
    collect = (time.perf_counter() - t) / steps
    vec.reset(seed=1)
    sync()
    t = time.perf_counter()
    for a in actions:
        vec.step(a)
    sync()
    return {"collection": collect, "env.step alone": (time.perf_counter() - t) / steps}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", default="PushCube-v1", choices=MANISKILL_TASKS)
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--substeps", type=int, default=None, help="MuJoCo-Warp steps per physics step (default: 16)")
    p.add_argument("--device", default="cuda:0" if wp.is_cuda_available() else "cpu")
    p.add_argument("--control-mode", default="pd_joint_delta_pos")
    p.add_argument("--action-sampling", default="sync-free", choices=("sync-free", "rsl-rl"))
    p.add_argument("--steps-per-env", type=int, default=None, help="the rollout length of one PPO iteration "
                   "(default: the task's recipe, 4; StackCube-v1 16)")  # fmt: skip
    p.add_argument("--replay-steps", type=int, default=48, help="steps of the same-states comparison")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--min-s", type=float, default=0.25, help="minimum seconds per timing sample")
    p.add_argument("--train-json", type=Path, default=None, help="a training run's train.json: its collection rate")
    p.add_argument("--out", default="bench/results")
    args = p.parse_args(argv)
    if args.steps_per_env is None:
        args.steps_per_env = task_recipe(args.task)["steps_per_env"]
    import torch
    from rsl_rl.runners import OnPolicyRunner
    from tensordict import TensorDict

    from wpctrl.train.sampling import act
    from wpctrl.train.task_env import TaskVecEnv
    from wpctrl.train.task_ppo import Collector, maniskill_ppo_cfg

    cuda = args.device.startswith("cuda")
    if not cuda:
        torch.set_num_threads(1)
    train = collection_rate(args.train_json, args.envs, args.device) if args.train_json else None
    vec = TaskVecEnv(args.task, args.envs, device=args.device, control_mode=args.control_mode, seed=0,
                     substeps=args.substeps)  # fmt: skip
    env = vec.env
    dev = env.wp_device

    def sync():
        wp.synchronize_device(dev)
        if cuda:
            torch.cuda.synchronize()

    physics, ctrl_calls = task_step_parts(env)
    steps = env.ctrl.num_substeps * env.physics.substeps

    fns, graphs = {}, {}
    for name, f in ((ROLLOUT, physics), (CONTROLLER, ctrl_calls)):
        f()
        with wp.ScopedCapture(device=dev) as cap:
            f()
        fns[name] = lambda g=cap.graph: wp.capture_launch(g)
        graphs[name] = cap.graph
    graphs[ENV_STEP] = env.graph
    hold = torch.zeros(args.envs, vec.num_actions, device=vec.device)
    hold[:, -1] = 1.0
    vec.reset(seed=0)
    fns[ENV_STEP] = lambda: vec.step(hold)

    with contextlib.redirect_stdout(io.StringIO()):
        alg = OnPolicyRunner(vec, maniskill_ppo_cfg(args.steps_per_env), log_dir=None, device=args.device).alg
    alg.train_mode()
    collector = Collector(vec, alg, args.action_sampling)
    sample = (lambda o: act(alg, o)) if args.action_sampling == "sync-free" else alg.act
    obs0 = vec.get_observations()
    rew0 = torch.zeros(args.envs, device=vec.device)
    done0 = torch.zeros(args.envs, dtype=torch.bool, device=vec.device)
    live = {"obs": obs0}

    def room():
        if alg.storage.step >= alg.storage.num_transitions_per_env:
            alg.storage.clear()

    def rsl_rl_alone():
        room()
        sample(obs0)
        value = alg.critic(TensorDict({"policy": obs0["policy"]}, batch_size=[args.envs])).squeeze(-1)
        alg.process_env_step(obs0, rew0 + alg.gamma * value * done0, done0, {})

    def collection_step():
        room()
        live["obs"] = collector.rollout(live["obs"], 1)

    def iteration():
        alg.storage.clear()
        live["obs"] = collector.rollout(live["obs"], args.steps_per_env)
        sync()

    fns[RSL_RL] = rsl_rl_alone
    fns[COLLECT] = collection_step
    fns[ITERATION] = iteration
    with torch.inference_mode():
        sec = {name: _time(f, sync, args.min_s, args.repeats) for name, f in fns.items()}
        host = {name: _host_time(f, sync, repeats=args.repeats) for name, f in fns.items()} if cuda else None
    with torch.inference_mode():
        same = _same_states(vec, collector, alg, sync, args.replay_steps)
    sec[ITERATION] /= args.steps_per_env
    if host:
        host[ITERATION] /= args.steps_per_env
    rollout = sec[ROLLOUT]
    launch = {name: _launch_host_time(g, sync, args.repeats) for name, g in graphs.items()} if cuda else None
    step, policy, collect, per_iteration = sec[ENV_STEP], sec[RSL_RL], sec[COLLECT], sec[ITERATION]
    result = {
        "task": args.task,
        "envs": args.envs,
        "control_mode": args.control_mode,
        "substeps": env.physics.substeps,
        "action_sampling": args.action_sampling,
        "steps_per_env": args.steps_per_env,
        "solver_steps_per_control_step": steps,
        "graph": env.graph is not None,
        "us_per_control_step": {k: v * 1e6 for k, v in sec.items()},
        "host_us_per_call": {k: v * 1e6 for k, v in host.items()} if host else None,
        "host_us_per_graph_launch_device_idle": {k: v * 1e6 for k, v in launch.items()} if launch else None,
        "rollout_env_steps_per_s": args.envs / rollout,
        "env_step_env_steps_per_s": args.envs / step,
        "controller_share_of_env_step": sec[CONTROLLER] / step,
        "collection_env_steps_per_s": args.envs / collect,
        "collection_over_rollout": rollout / collect,
        "collection_over_env_step": step / collect,
        "iteration_collection_env_steps_per_s": args.envs / per_iteration,
        "iteration_collection_over_rollout": rollout / per_iteration,
        "policy_share_of_collection": 1.0 - step / collect,
        "same_states_us_per_step": {k: v * 1e6 for k, v in same.items()},
        "same_states_collection_over_env_step": same["env.step alone"] / same["collection"],
        "collection_us_if_serial": (step + policy) * 1e6,
        "collection_us_if_overlapped": max(step, policy) * 1e6,
    }
    if train:
        rate = train["collection_env_steps_per_s"]
        result["training"] = train
        result["training_collection_over_rollout"] = rate / result["rollout_env_steps_per_s"]
    meta = machine_info(args.device)
    name = meta.get("device_name", args.device)
    rows = [
        [k, f"{v * 1e6:,.1f}", f"{host[k] * 1e6:,.1f}" if host else "–", f"{args.envs / v:,.0f}", f"{v / step:.1%}"]
        for k, v in sec.items()
    ]
    md = [
        f"# PPO collection on {args.task} vs the same envs without a policy: {args.envs} envs, {name}\n",
        meta_markdown(meta) + "\n",
        f"Mode `{args.control_mode}`, {steps} MuJoCo-Warp steps per control step ({env.physics.substeps} per 10 ms "
        "physics step), " + ("each part a CUDA graph.\n" if cuda else "the env step a CPU graph.\n"),
        md_table(["part", "µs per control step", "host µs per call", "env-steps/s", "share of env.step"], rows),
        "(host µs: what the host spends per call when it does not wait for the device.)\n",
        f"Controller share of the env step: {result['controller_share_of_env_step']:.2%}.\n",
        f"PPO collection: {args.envs / collect:,.0f} env-steps/s = {result['collection_over_rollout']:.0%} of the "
        f"MuJoCo-Warp rollout, {result['collection_over_env_step']:.0%} of env.step without a policy. Per step "
        f"{collect * 1e6:,.0f} µs, against {(step + policy) * 1e6:,.0f} µs if rsl-rl's work and the env step ran one "
        f"after the other and {max(step, policy) * 1e6:,.0f} µs if they overlapped entirely. One iteration's rollout "
        f"of {args.steps_per_env} steps with its sync: {args.envs / per_iteration:,.0f} env-steps/s = "
        f"{result['iteration_collection_over_rollout']:.0%} of the rollout. Action sampling: {args.action_sampling}.\n",
    ]
    md.append(
        f"The same {args.replay_steps} steps from the same reset (µs per step): collection "
        f"{same['collection'] * 1e6:,.0f}, env.step with the recorded actions alone "
        f"{same['env.step alone'] * 1e6:,.0f}: "
        f"collection = {result['same_states_collection_over_env_step']:.0%} of the env step's rate on the states the "
        "policy drives.\n"
    )
    if launch:
        md.append("Host µs to launch a captured graph with the device idle (a sync before each launch): "
                  + ", ".join(f"{k} {v * 1e6:,.0f}" for k, v in launch.items()) + ".\n")  # fmt: skip
    if train:
        md.append(
            f"The training run ({args.train_json}, median of its {train['iterations']} iterations' collection): "
            f"{rate:,.0f} env-steps/s = {result['training_collection_over_rollout']:.0%} of the MuJoCo-Warp "
            "rollout.\n"
        )
    stem = f"task_train_rate_{args.task}_{'cuda' if cuda else 'cpu'}_{args.action_sampling}"
    jpath, mpath = write_results(args.out, stem, meta, [result], "\n".join(md))
    print("\n".join(md))
    print(f"wrote {jpath} and {mpath}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
