"""Mutations: what the replay reads and refuses (``wpctrl/tasks/recording.py``, ``wpctrl/tasks/_validate.py``,
``wpctrl/tasks/policy_episodes.py``) and the flags its report compares (``wpctrl/tasks/replay.py``)."""

from .model import M

_REFUSALS = ("tests/test_replay_refusals.py",)
_POLICY = ("tests/test_policy_replay.py",)
_FLAGS = ("tests/test_task_place_sphere.py", "tests/test_tasks_replay.py")

MUTATIONS = [
    M(
        "replay_action_width_unchecked",
        "wpctrl/tasks/recording.py",
        "        if a.shape[1] != width:\n",
        "        if a.shape[1] > width:\n",
        "a recording with fewer action values per step than its control mode takes is replayed",
        _REFUSALS,
    ),
    M(
        "state_dict_other_task_actors",
        "wpctrl/tasks/_validate.py",
        "        if extra:\n",
        "        if False:\n",
        "a state dict holding another task's actors is taken",
        _REFUSALS,
    ),
    M(
        "policy_episodes_success_shift",
        "wpctrl/tasks/policy_episodes.py",
        "        flags = [False] + [bool(s) for s in success[i]]\n",
        "        flags = [bool(s) for s in success[i]] + [bool(success[i][-1])]\n",
        "the npz's success after step t read as the success at step t (one step early)",
        _POLICY,
    ),
    M(
        "replay_flags_only_success_checked",
        "wpctrl/tasks/recording.py",
        "    for key, flags in info.items():\n",
        '    for key, flags in [("success", info["success"])]:\n',
        "a recording's other flags (is_grasped, ...) are taken unchecked: a truncated flag list reaches the replay",
        _REFUSALS,
    ),
    M(
        "replay_flags_read_success",
        "wpctrl/tasks/replay.py",
        "            flags[k][:, t] = info[k].cpu().numpy()\n",
        '            flags[k][:, t] = info["success"].cpu().numpy()\n',
        "every replayed flag is read from Newton's success instead of its own",
        _FLAGS,
    ),
    M(
        "replay_flags_recorded_reset_shift",
        "wpctrl/tasks/replay.py",
        '                flags_recorded={f: [bool(g) for g in ep["info"][f][1:]] for f in names},\n',
        '                flags_recorded={f: [bool(g) for g in ep["info"][f][:-1]] for f in names},\n',
        "ManiSkill's flags read one step early (the reset's flag taken as step 1's)",
        _FLAGS,
    ),
    M(
        "replay_first_parting_step_early",
        "wpctrl/tasks/replay.py",
        "        return {name: int(steps[0]) + 1 for name, steps in parted.items() if steps.size}\n",
        "        return {name: int(steps[0]) for name, steps in parted.items() if steps.size}\n",
        "the first step at which a flag parts is reported one step early",
        _FLAGS,
    ),
]
