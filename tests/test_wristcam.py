"""ManiSkill's ``panda_wristcam``, the default robot of StackCube-v1 and PegInsertionSide-v1: the Panda of
``panda_v3.urdf``, with a RealSense camera (a 0.564 kg link and a collision box) on the hand, turned the other way at
rest (joint 7 at -pi/4). ``wpctrl.tasks.make`` builds each task on ManiSkill's default robot unless given
``robot_uids``; the state dict names the robot, a state of the other one is refused; ManiSkill's trajectory files of
the default env (``RecordEpisode``, as its motion-planning demos are written) replay on it. Checked against the real
ManiSkill 3.0.1 (PhysX CPU, rendering stubbed out)."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("mani_skill")
pytest.importorskip("h5py")

from maniskill_tasks_side import make_maniskill  # noqa: E402

import wpctrl  # noqa: E402
import wpctrl.tasks as T  # noqa: E402
from wpctrl.tasks.names import ROBOTS, TASK_ACTORS, TASK_IDS  # noqa: E402

TASK = "StackCube-v1"
MODE = "pd_joint_delta_pos"
FAST = T.task_physics(TASK, substeps=4)


def _maniskill_default(task: str) -> str:
    import mani_skill.envs  # noqa: F401  (registers the tasks)
    from mani_skill.utils.registration import REGISTERED_ENVS

    return inspect.signature(REGISTERED_ENVS[task].cls.__init__).parameters["robot_uids"].default


def test_each_task_builds_maniskills_default_robot():
    """Every task's default robot is the ``robot_uids`` default of ManiSkill's env class, in the task module and in
    the host-only names the replay reads; an unknown robot is refused, listing the two."""
    for task in TASK_IDS:
        assert T.TASKS[task].robot_uids == TASK_ACTORS[task].robot == _maniskill_default(task), task
    assert {_maniskill_default(t) for t in TASK_IDS} == set(ROBOTS)
    with pytest.raises(wpctrl.ConfigError, match=r"robot_uids expected one of \['panda', 'panda_wristcam'\].*'fetch'"):
        T.make(TASK, robot_uids="fetch")


@pytest.fixture(scope="module")
def pair():
    """StackCube-v1 on its default robot in both simulators."""
    ms = make_maniskill(TASK, MODE)
    nw = T.make(TASK, num_envs=1, control_mode=MODE, physics=FAST, auto_reset=False)
    yield ms, nw
    ms.close()
    nw.close()


def test_the_camera_is_maniskills_link(pair):
    """Newton's ``panda_wristcam`` carries ManiSkill's camera link: its mass, and one collision shape more than the
    ``panda`` scene (the camera's box); the panda's massless finger-pad links are not part of it."""
    ms, nw = pair
    links = ms.unwrapped.agent.robot.links_map
    labels = [lb.rsplit("/", 1)[-1] for lb in nw.model.body_label]
    camera = labels.index("camera_link")
    assert nw.model.body_mass.numpy()[camera] == pytest.approx(float(links["camera_link"].mass[0]), rel=1e-5)
    assert float(links["camera_link"].mass[0]) == pytest.approx(0.564, rel=1e-5)
    assert "panda_leftfinger_pad" not in labels and "panda_leftfinger_pad" not in links
    plain = T.make(TASK, num_envs=1, control_mode=MODE, physics=FAST, auto_reset=False, robot_uids="panda")
    try:
        assert "camera_link" not in [lb.rsplit("/", 1)[-1] for lb in plain.model.body_label]
        assert nw.scene.shapes_per_env == plain.scene.shapes_per_env + 1
        assert plain.robot_uids == "panda" and nw.robot_uids == "panda_wristcam"
    finally:
        plain.close()


def test_the_reset_turns_the_hand_as_maniskills(pair):
    """ManiSkill's table scene rests ``panda_wristcam``'s joint 7 at -pi/4 (``panda``'s at +pi/4); Newton's resets
    draw around the same qpos: 64 envs' mean within 4 standard errors of the N(0, 0.02) noise."""
    ms, _ = pair
    qm = ms.unwrapped.get_state_dict()["articulations"]["panda_wristcam"][0, 13:20].numpy()
    assert abs(qm[6] + math.pi / 4) < 0.1
    env = T.make(TASK, num_envs=64, control_mode=MODE, physics=FAST, auto_reset=False)
    try:
        env.reset(seed=3)
        q = env.get_state_dict()["articulations"]["panda_wristcam"][:, 13:20].numpy()
    finally:
        env.close()
    rest = np.array([0.0, math.pi / 8, 0.0, -5 * math.pi / 8, 0.0, 3 * math.pi / 4, -math.pi / 4])
    assert np.abs(q.mean(0) - rest).max() < 4 * 0.02 / math.sqrt(64)


def test_the_same_state_and_actions_give_maniskills_obs_and_motion(pair):
    """ManiSkill's state after its reset, loaded into Newton, gives ManiSkill's observation (1e-5); 20 random
    ``pd_joint_delta_pos`` actions then move both arms alike (measured 6 mrad at most on either robot; a hand turned
    the wrong way, or the camera's collision box missing where it meets the arm, parts by far more). A ``panda``
    state dict is refused by the ``panda_wristcam`` env, naming both robots, and nothing is written."""
    ms, nw = pair
    base = ms.unwrapped
    ms.reset(seed=11)
    state = base.get_state_dict()
    assert list(state["articulations"]) == ["panda_wristcam"]
    nw.set_state_dict(state)
    np.testing.assert_allclose(nw.get_obs().numpy(), base.get_obs().numpy(), atol=1e-5)
    before = nw.get_state_dict()
    with pytest.raises(wpctrl.ConfigError, match=r"is a state of the robot 'panda', expected 'panda_wristcam'"):
        nw.set_state_dict({"actors": state["actors"],
                           "articulations": {"panda": state["articulations"]["panda_wristcam"]}})  # fmt: skip
    assert torch.equal(nw.get_state_dict()["articulations"]["panda_wristcam"],
                       before["articulations"]["panda_wristcam"])  # fmt: skip
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = torch.tensor(rng.uniform(-1.0, 1.0, (1, 8)), dtype=torch.float32)
        ms.step(a)
        nw.step(a)
    qm = base.get_state_dict()["articulations"]["panda_wristcam"][0, 13:22].numpy()
    qn = nw.get_state_dict()["articulations"]["panda_wristcam"][0, 13:22].numpy()
    assert np.abs(qn[:7] - qm[:7]).max() < 0.02
    assert np.abs(qn[7:] - qm[7:]).max() < 0.002


def test_a_trajectory_file_of_the_default_env_replays_on_its_robot(tmp_path):
    """Two 12-step episodes of ManiSkill's default StackCube-v1 env (``panda_wristcam``), written by its
    ``RecordEpisode``: ``load_episodes`` reads the robot's states, ``replay`` builds the env on that robot and ends
    with the arm where ManiSkill's ended (as the side-by-side test's bound), and an env of the other robot is
    refused, naming both."""
    from mani_skill.utils.wrappers import RecordEpisode

    env = RecordEpisode(make_maniskill(TASK, MODE), str(tmp_path), trajectory_name=TASK, save_video=False)
    rng = np.random.default_rng(1)
    try:
        for seed in (4, 5):
            env.reset(seed=seed)
            for _ in range(12):
                env.step(torch.tensor(rng.uniform(-1.0, 1.0, (1, 8)), dtype=torch.float32))
    finally:
        env.close()
    h5 = tmp_path / f"{TASK}.h5"
    data = T.load_episodes(h5)
    assert [list(ep["init_state_dict"]["articulations"]) for ep in data["episodes"]] == [["panda_wristcam"]] * 2
    newton = T.make(TASK, num_envs=2, control_mode=MODE, physics=FAST, auto_reset=False, ignore_terminations=True)
    plain = T.make(TASK, num_envs=2, control_mode=MODE, physics=FAST, auto_reset=False, ignore_terminations=True,
                   robot_uids="panda")  # fmt: skip
    try:
        with pytest.raises(wpctrl.ConfigError, match=r"env is StackCube-v1 / panda / .* the file StackCube-v1 / "
                                                      r"panda_wristcam"):  # fmt: skip
            T.replay(data, env=plain)
        report = T.replay(data, env=newton)
        assert len(report.episodes) == 2
        import h5py

        with h5py.File(h5, "r") as f:
            last = np.stack([f[f"traj_{i}/env_states/articulations/panda_wristcam"][-1, 13:20] for i in (0, 1)])
        q = newton.get_state_dict()["articulations"]["panda_wristcam"][:, 13:20].numpy()
        assert np.abs(q - last).max() < 0.02
    finally:
        newton.close()
        plain.close()
