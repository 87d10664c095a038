"""Mutations: what the replay reads and refuses (``wpctrl/tasks/recording.py``, ``wpctrl/tasks/_validate.py``,
``wpctrl/tasks/policy_episodes.py``)."""

from .model import M

_REFUSALS = ("tests/test_replay_refusals.py",)
_POLICY = ("tests/test_policy_replay.py",)

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
]
