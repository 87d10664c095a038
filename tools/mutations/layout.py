"""Mutations: the package's layout (robot descriptions read by the config layer, the substep kernel with a network)."""

from .model import M

MUTATIONS = [
    M(
        "descriptions_ignore_registered_robots",
        "wpctrl/config/robot_description.py",
        "    return Descriptions(urdf_path, tuple(_REGISTERED), error)\n",
        "    return Descriptions(urdf_path, (), error)\n",
        "an EE config without a readable urdf_path no longer finds a link merged away in the registered robots",
        ("tests/test_ee.py",),
    ),
    M(
        "fused_net_threads_skip_the_envs",
        "wpctrl/kernels/pd_substep.py",
        "            env = env - num_envs * wp.static(N)\n",
        "            env = env - num_envs * wp.static(N) + 1\n",
        "the substep kernel with a network's rows in its launch steps the wrong envs",
        ("tests/test_actuator_net_fused.py",),
    ),
]
