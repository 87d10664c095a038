"""Mutations: the solver built before the controller; end effectors of envs placed apart."""

from .model import M

MUTATIONS = [
    M(
        "given_solver_not_told_of_gravity",
        "wpctrl/engine/core.py",
        "flags |= newton.ModelFlags.BODY_INERTIAL_PROPERTIES",
        "flags |= newton.ModelFlags.JOINT_DOF_FORCE_PROPERTIES",
        "a solver built before the controller is not told of the gravity compensation (mujoco:gravcomp)",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "given_solver_not_notified",
        "wpctrl/engine/core.py",
        "            if solver is not None:\n                solver.notify_model_changed(self.model_flags())\n",
        "",
        "a solver given as solver= is not notified of the drive properties and gravity at build",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "attach_solver_not_notified",
        "wpctrl/engine/core.py",
        "        self.solver = solver\n        solver.notify_model_changed(self.model_flags())\n",
        "        self.solver = solver\n",
        "attach_solver keeps the solver for later notices but does not notify it now",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "ee_root_is_env_0_world",
        "wpctrl/engine/parts/ee.py",
        "x0 = _design_frame(spec, _short(jlabels[table[0, 0]]))",
        "x0 = None",
        "EE poses of a world-merged fixed base are in env 0's world frame (replicate's centred grid moves env 0)",
        ("tests/test_construction_orders.py",),
    ),
    M(
        "ee_env_placement_ignored",
        "wpctrl/engine/parts/ee.py",
        "                root[e] = np.array([*r.p, *r.q], np.float32)\n",
        "                pass\n",
        "EE poses of envs placed apart are not moved into each env's base frame",
        ("tests/test_construction_orders.py",),
    ),
]
