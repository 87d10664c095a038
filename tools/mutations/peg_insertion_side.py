"""Mutations: PegInsertionSide-v1 (``wpctrl/tasks/peg_insertion_side.py``) and the scene drawn from the seed
(``wpctrl/tasks/geometry.py``, the reconfiguration in ``wpctrl/tasks/env.py``)."""

from .model import M

_TESTS = ("tests/test_task_peg_insertion_side.py",)
_PHYSICS = ("tests/test_tasks.py", "tests/test_task_peg_insertion_side.py")

MUTATIONS = [
    M(
        "peg_physics_elliptic_cone",
        "wpctrl/tasks/peg_insertion_side.py",
        ', "cone": "pyramidal", "arm_drive"',
        ', "arm_drive"',
        "PegInsertionSide's grip under the elliptic cone: the carried peg turns in the hand and insertions miss",
        _PHYSICS,
    ),
    M(
        "peg_physics_soft_finger_contacts",
        "wpctrl/tasks/peg_insertion_side.py",
        '"finger_solimp": (0.95, 0.95, 0.001), ',
        "",
        "PegInsertionSide's fingers keep the defaults' soft contacts (0.7): half of a larger demo sample misses",
        _PHYSICS,
    ),
    M(
        "peg_physics_tgs_arm_drive",
        "wpctrl/tasks/peg_insertion_side.py",
        ', "arm_drive": "mujoco"}',
        "}",
        "PegInsertionSide's arm under the TGS pass, with the grip chosen for MuJoCo's drive: a third of the demos miss",
        _PHYSICS,
    ),
    M(
        "task_physics_ignored_by_make",
        "wpctrl/tasks/factory.py",
        "        physics = task_physics(env_id)\n",
        "        physics = TaskPhysics()\n",
        "make without physics runs the common defaults, not the task's own (PegInsertionSide's grip lost)",
        _PHYSICS,
    ),
    M(
        "task_physics_changes_drop_the_tasks",
        "wpctrl/tasks/factory.py",
        "    settings = {**TASKS[env_id].physics, **changes}\n",
        "    settings = dict(changes)\n",
        "task_physics(env_id, substeps=8) forgets the task's departures (training at 8 substeps loses the grip)",
        _PHYSICS,
    ),
    M(
        "task_physics_unchecked_at_registration",
        "wpctrl/tasks/registry.py",
        '    physics_from(cls.physics, f"{where}: physics")\n',
        "",
        "a task declaring a field TaskPhysics does not have, or a bad value, is registered (and fails only when built)",
        _PHYSICS,
    ),
    M(
        "peg_insertion_depth",
        "wpctrl/tasks/peg_insertion_side.py",
        "h[0] >= INSERTED_X and",
        "h[0] >= 2.0 * INSERTED_X and",
        "PegInsertionSide's success accepts a head 3 cm short of the hole's centre",
        _TESTS,
    ),
    M(
        "peg_insertion_draw_order",
        "wpctrl/tasks/peg_insertion_side.py",
        "            length = rng.uniform(*LENGTH_RANGE)\n            radius = rng.uniform(*RADIUS_RANGE)\n",
        "            radius = rng.uniform(*RADIUS_RANGE)\n            length = rng.uniform(*LENGTH_RANGE)\n",
        "the peg's half width drawn before its half length (another stream than ManiSkill's)",
        _TESTS,
    ),
    M(
        "peg_insertion_hole_offset_sign",
        "wpctrl/tasks/peg_insertion_side.py",
        "Box((depth, thickness - hc[0], outer), (0.0, offset + hc[0], 0.0)),",
        "Box((depth, thickness - hc[0], outer), (0.0, offset - hc[0], 0.0)),",
        "one wall of the hole on the wrong side of its offset",
        _TESTS,
    ),
    M(
        "peg_insertion_grasp_angle",
        "wpctrl/tasks/peg_insertion_side.py",
        "grasped = is_grasping_within(s, e, PEG, wp.static(_GRASP_COS))",
        "grasped = is_grasping(s, e, PEG)",
        "the reward's grasp at ManiSkill's default 85 degrees instead of the task's 20",
        _TESTS,
    ),
    M(
        "peg_insertion_geometry_not_notified",
        "wpctrl/tasks/env.py",
        "            self.solver.notify_model_changed(GEOMETRY_FLAGS)\n",
        "            pass\n",
        "a reconfiguration resizes Newton's shapes but the solver keeps the old ones",
        _TESTS,
    ),
    M(
        "peg_insertion_peg_mass_kept",
        "wpctrl/tasks/geometry.py",
        "            mass[b], inv_mass[b], com[b] = m, 1.0 / m, c\n",
        "            pass\n",
        "the peg keeps the mass of the shapes it was built with",
        _TESTS,
    ),
    M(
        "peg_insertion_reconfigure_every_reset",
        "wpctrl/tasks/env.py",
        'reconfigure = bool(options.get("reconfigure", False)) or (',
        'reconfigure = True or (',
        "every reset draws the scene again, whatever reconfiguration_freq says",
        _TESTS,
    ),
]

MUTATIONS += [
    M(
        "finger_torsion_on_every_shape",
        "wpctrl/tasks/scene.py",
        "        ns.condim.assign(np.where(fingers, 4, ns.condim.numpy()).astype(np.int32))\n",
        "        ns.condim.assign(np.full(model.shape_count, 4, np.int32))\n",
        "finger_torsion gives every shape condim 4, not just the fingers'",
        ("tests/test_tasks.py",),
    ),
    M(
        "finger_torsion_condim_kept",
        "wpctrl/tasks/scene.py",
        "        ns.condim.assign(np.where(fingers, 4, ns.condim.numpy()).astype(np.int32))\n",
        "        pass\n",
        "finger_torsion sets a torsional coefficient MuJoCo never uses (condim left at 3)",
        ("tests/test_tasks.py",),
    ),
]
