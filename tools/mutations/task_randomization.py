"""Mutations: the per-env task physics drawn at every reset (``wpctrl/tasks/randomizer.py``) and the observation
entries training hides (``wpctrl/train/hidden_inputs.py``, ``wpctrl/train/task_env.py``, ``wpctrl/train/actor.py``)."""

from .model import M

_DRAWS = ("tests/test_task_randomization.py",)
_HIDDEN = ("tests/test_train_tasks.py", "tests/test_export_actor.py")

MUTATIONS = [
    M(
        "randomizer_invweight_kept",
        "wpctrl/tasks/randomizer.py",
        "        body_invweight0[e, b] = base_invweight[e, b] / m",
        "        body_invweight0[e, b] = base_invweight[e, b]",
        "a heavier cube keeps the inverse weights of the nominal one (its contacts softened as before)",
        _DRAWS,
    ),
    M(
        "randomizer_world_subtree_mass_kept",
        "wpctrl/tasks/randomizer.py",
        "    body_subtreemass[e, 0] = base_subtreemass[e, 0] + added",
        "    body_subtreemass[e, 0] = base_subtreemass[e, 0]",
        "the world's subtree mass ignores the objects' new mass",
        _DRAWS,
    ),
    M(
        "randomizer_same_stream_as_the_reset",
        "wpctrl/tasks/randomizer.py",
        "    rng = wp.rand_init(seed[e], reset_count[e] + RAND_STREAM)",
        "    rng = wp.rand_init(seed[e])",
        "every episode of an env draws the same factors (the episode count left out)",
        _DRAWS,
    ),
    M(
        "randomizer_every_env",
        "wpctrl/tasks/randomizer.py",
        "    if not mask[e]:\n        return\n    rng",
        "    rng",
        "a partial or auto reset draws new factors for every env, not only the reset ones",
        _DRAWS,
    ),
    M(
        "randomizer_base_not_recaptured",
        "wpctrl/tasks/env.py",
        "                self._randomizer.capture_base()",
        "                pass",
        "after the scene is drawn again the factors scale the old scene's masses",
        _DRAWS,
    ),
    M(
        "hidden_inputs_arm_velocities",
        "wpctrl/train/hidden_inputs.py",
        "    return [qvel.start + PANDA_JOINTS.index(j) for j in PANDA_GRIPPER_JOINTS]",
        "    return [qvel.start + PANDA_JOINTS.index(j) - 2 for j in PANDA_GRIPPER_JOINTS]",
        "two arm joints' velocities hidden instead of the fingers'",
        _HIDDEN,
    ),
    M(
        "hidden_inputs_final_observation_shown",
        "wpctrl/train/task_env.py",
        'extras = {"final_observations": self.hide(info["final_observation"]), "terminated": terminated,',
        'extras = {"final_observations": info["final_observation"], "terminated": terminated,',
        "the critic bootstraps from final observations that show the hidden entries",
        _HIDDEN,
    ),
    M(
        "hidden_inputs_not_in_the_export",
        "wpctrl/train/actor.py",
        "        return self.mlp(self.obs_normalizer(self.hidden_inputs(obs)))",
        "        return self.mlp(self.obs_normalizer(obs))",
        "the exported policy reads the entries training hid",
        _HIDDEN,
    ),
]
