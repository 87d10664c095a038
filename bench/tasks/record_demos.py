"""Record ManiSkill's own motion-planning demos in the real ManiSkill, as ManiSkill's trajectory files.

ManiSkill solves its table-top tasks with a motion planner (``mani_skill.examples.motionplanning.panda``: mplib screw
plans, stepping the env in ``pd_joint_pos``). This runs that solution, unchanged, for every seed of a range on
ManiSkill's CPU PhysX (``render_backend="none"``, one env, the visual side stubbed out as in the tests), records it
with ManiSkill's ``RecordEpisode`` and keeps the seeds whose plan ran and whose last step is a success, as ManiSkill's
own demo generation does. ``wpctrl replay DIR/<task>.h5`` then replays them on Newton: a sample of the demos' kind
larger than the public one, drawn from seeds of your choice.

    python bench/tasks/record_demos.py --task PegInsertionSide-v1 --seeds 200:232 --out /tmp/demos

mplib 0.1.1 (the planner mani-skill 3.0.1 pins) crashes with a segmentation fault when it builds its planner under
numpy 2, so this needs numpy 1 on the path: ``pip install --target /tmp/np1 "numpy<2"``, then run it with
``PYTHONPATH=/tmp/np1``. Nothing of wpctrl's is used beyond the visual stub.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings


def solutions() -> dict:
    """ManiSkill's motion-planning solution of each task wpctrl builds (its own ``MP_SOLUTIONS`` of
    ``mani_skill.examples.motionplanning.panda.run``, restricted to :data:`wpctrl.tasks.names.TASK_MODULES`)."""
    from mani_skill.examples.motionplanning.panda.run import MP_SOLUTIONS

    from wpctrl.tasks.names import TASK_MODULES

    return {task: solve for task, solve in MP_SOLUTIONS.items() if task in TASK_MODULES}


def parse_seeds(text: str) -> range:
    """``"200:232"`` -> seeds 200 .. 231."""
    try:
        first, stop = (int(v) for v in text.split(":"))
    except ValueError:
        raise SystemExit(f"--seeds: expected FIRST:STOP (e.g. 200:232), got {text!r}") from None
    if stop <= first:
        raise SystemExit(f"--seeds: expected STOP > FIRST, got {text!r}")
    return range(first, stop)


def record(task: str, seeds: range, out: str, robot: str = "panda", max_steps: int = 500) -> tuple[list, list]:
    """Run ManiSkill's solution of ``task`` for every seed, recording into ``out/<task>.h5`` + ``.json``; returns the
    seeds kept and the seeds whose plan failed or did not end in success."""
    import numpy as np

    if int(np.__version__.split(".")[0]) >= 2:
        raise SystemExit(f"numpy {np.__version__}: mplib 0.1.1 crashes building its planner under numpy 2; "
                         "install numpy 1 aside (pip install --target /tmp/np1 'numpy<2') and run with "
                         "PYTHONPATH=/tmp/np1")  # fmt: skip
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401  (registers the tasks)
    from mani_skill.utils.wrappers.record import RecordEpisode

    from wpctrl.tasks.maniskill_side import no_visuals

    solve = solutions()[task]
    kept, failed = [], []
    with warnings.catch_warnings(), no_visuals():  # PegInsertionSide rebuilds its scene at every reset
        warnings.simplefilter("ignore")
        env = gym.make(task, sim_backend="physx_cpu", render_backend="none", num_envs=1, obs_mode="none",
                       control_mode="pd_joint_pos", robot_uids=robot, max_episode_steps=max_steps,
                       reward_mode="dense")  # fmt: skip
        env = RecordEpisode(env, output_dir=out, trajectory_name=task, save_video=False, source_type="motionplanning",
                            record_reward=False, save_on_reset=False)  # fmt: skip
        start = time.time()
        for seed in seeds:
            try:
                result = solve(env, seed=seed, debug=False, vis=False)
            except Exception as e:  # a plan that cannot be found, as ManiSkill's own generator counts it
                print(f"seed {seed}: the planner failed ({e})", file=sys.stderr)
                result = -1
            ok = result != -1 and bool(result[-1]["success"].item())
            env.flush_trajectory(save=ok)
            (kept if ok else failed).append(seed)
            print(f"seed {seed}: {'kept' if ok else 'dropped'} ({time.time() - start:.0f} s)", flush=True)
        env.close()
    return kept, failed


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", required=True, choices=sorted(solutions()))
    p.add_argument("--seeds", required=True, help="FIRST:STOP, the reset seeds to try")
    p.add_argument("--out", required=True, help="folder for <task>.h5 and <task>.json")
    p.add_argument("--robot", default="panda", help="robot_uids (default: panda, as the public demos)")
    a = p.parse_args(argv)
    kept, failed = record(a.task, parse_seeds(a.seeds), a.out, a.robot)
    print(f"{a.task}: kept {len(kept)} seeds {kept}; dropped {failed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
