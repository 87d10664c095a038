"""Contact probes: the Panda's fingers on PickCube's cube, driven the same way in the real ManiSkill (PhysX CPU) and on
Newton, read the same way on both.

A probe is a list of absolute TCP targets (``pd_ee_pose``: position in the robot's base frame, the gripper pointing
down as at ManiSkill's rest pose, the gripper's target). ManiSkill drives the arm to the probe's start and settles
there; its state dict then starts both simulators, and both step through the same targets. After every control step
each side reports the fingers' and the cube's poses and the fingers' total contact force on the cube; from those,
:func:`reading` derives what the probes compare: how deep a fingertip sits in the cube (the overlap of the two
boxes, simulator-independent), how far the fingertip's footprint reaches over the cube's top face, the cube's tilt
and its place relative to the TCP.

``python tests/contact_probes.py`` prints every probe side by side (the table in docs/tasks.md).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

CUBE_HALF = 0.02
"""PickCube's cube half size [m] (``PICK_CUBE_CONFIGS["panda"]["cube_half_size"]``)."""
TIP_CENTER = np.array([0.0, 7.58e-3, 45.25e-3])
TIP_HALF = np.array([8.75e-3, 7.6e-3, 9.25e-3])
"""The rubber tip, the lowest collision box of ``panda_leftfinger`` in ManiSkill's ``panda_v2.urdf`` (centre in the
finger's frame, half extents); the right finger's is mirrored in y."""
CUBE_AT = np.array([0.05, 0.0, CUBE_HALF])
"""Where the probes put the cube (resting on the table, unrotated)."""


def _xyzw(q_wxyz) -> np.ndarray:
    return np.array([q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0]])


def _corners(center, half) -> np.ndarray:
    return center + np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * half


def _depth_inside(points_local: np.ndarray, half: np.ndarray) -> float:
    """The deepest of ``points`` (in a box's frame) inside the box: its distance to the nearest face, 0 if none."""
    return max(0.0, float(np.min(half - np.abs(points_local), axis=1).max()))


def tip_depth(finger_pose, cube_pose, side: float) -> float:
    """How deep one finger's tip box and the cube overlap [m]: the deepest corner of either inside the other."""
    from scipy.spatial.transform import Rotation

    rf, rc = Rotation.from_quat(_xyzw(finger_pose[3:])), Rotation.from_quat(_xyzw(cube_pose[3:]))
    tip_center = TIP_CENTER * np.array([1.0, side, 1.0])
    tip_world = finger_pose[:3] + rf.apply(_corners(tip_center, TIP_HALF))
    cube_world = cube_pose[:3] + rc.apply(_corners(np.zeros(3), np.full(3, CUBE_HALF)))
    in_cube = rc.inv().apply(tip_world - cube_pose[:3])
    in_tip = rf.inv().apply(cube_world - finger_pose[:3]) - tip_center
    return max(_depth_inside(in_cube, np.full(3, CUBE_HALF)), _depth_inside(in_tip, TIP_HALF))


def reading(raw: dict) -> dict:
    """What a probe compares, from one side's raw poses (``[p, q wxyz]``) and force (on the cube, world frame)."""
    from scipy.spatial.transform import Rotation

    f1, f2, cube, tcp, force = (np.asarray(raw[k], float) for k in ("f1", "f2", "cube", "tcp", "force"))
    rc = Rotation.from_quat(_xyzw(cube[3:]))
    tip = f1[:3] + Rotation.from_quat(_xyzw(f1[3:])).apply(_corners(TIP_CENTER, TIP_HALF))
    local = rc.inv().apply(tip - cube[:3])
    lo, hi = local.min(axis=0), local.max(axis=0)
    reach = min(min(hi[i], CUBE_HALF) - max(lo[i], -CUBE_HALF) for i in (0, 1))
    up = rc.apply([0.0, 0.0, 1.0])
    return {
        "force": float(np.linalg.norm(force)),
        "depth": max(tip_depth(f1, cube, 1.0), tip_depth(f2, cube, -1.0)),
        "reach": float(reach),
        "tilt_deg": math.degrees(math.acos(float(np.clip(up[2], -1.0, 1.0)))),
        "cube": cube[:3].copy(),
        "cube_in_tcp": Rotation.from_quat(_xyzw(tcp[3:])).inv().apply(cube[:3] - tcp[:3]),
        "finger_q": np.asarray(raw["qpos"], float)[7:9],
        "finger_qd": np.asarray(raw["qvel"], float)[7:9],
        "grasped": bool(raw["grasped"]),
    }


def _maniskill_raw(base) -> dict:
    a = base.agent
    scene = base.scene
    force = (scene.get_pairwise_contact_forces(a.finger1_link, base.cube)
             + scene.get_pairwise_contact_forces(a.finger2_link, base.cube))[0].numpy()  # fmt: skip
    return {"f1": a.finger1_link.pose.raw_pose[0].numpy(), "f2": a.finger2_link.pose.raw_pose[0].numpy(),
            "cube": base.cube.pose.raw_pose[0].numpy(), "tcp": a.tcp.pose.raw_pose[0].numpy(),
            "force": -force, "qpos": a.robot.get_qpos()[0].numpy(), "qvel": a.robot.get_qvel()[0].numpy(),
            "grasped": bool(a.is_grasping(base.cube)[0])}  # fmt: skip


def _newton_raw(env) -> dict:
    sc = env.scene
    body_q = env.state.body_q.numpy().reshape(env.num_envs, sc.bodies_per_env, 7)[0]

    def pose(b):  # Newton's [p, q xyzw] -> [p, q wxyz]
        p = body_q[b]
        return np.concatenate([p[:3], [p[6], p[3], p[4], p[5]]])

    # (2, actors): the normal force on each finger from the cube (PhysX reports the normal impulses only)
    force = env._sensor.force_matrix.numpy() - env._sensor.force_matrix_friction.numpy()
    q0, qd0 = sc.robot_coord0, sc.robot_dof0
    return {"f1": pose(sc.finger_bodies0[0]), "f2": pose(sc.finger_bodies0[1]), "cube": pose(sc.actor_body0["cube"]),
            "tcp": pose(sc.tcp_body0), "force": -(force[0, 0] + force[1, 0]),
            "qpos": env.state.joint_q.numpy()[q0 : q0 + 9],
            "qvel": env.state.joint_qd.numpy()[qd0 : qd0 + 9],
            "grasped": bool(env.evaluate()["is_grasped"].numpy()[0])}  # fmt: skip


class Probe:
    """One ManiSkill env (``PickCube-v1``, ``pd_ee_pose``) and one Newton env beside it, for probes."""

    def __init__(self, physics=None):
        import wpctrl.tasks as T
        from wpctrl.tasks.maniskill_side import make_maniskill

        self.ms = make_maniskill("PickCube-v1", "pd_ee_pose")
        self.newton = T.make("PickCube-v1", num_envs=1, control_mode="pd_ee_pose", auto_reset=False,
                             ignore_terminations=True, physics=physics)  # fmt: skip
        self.newton.reset(seed=0)

    def _action(self, xyz, gripper: float):
        import torch

        base = self.ms.unwrapped
        root = base.agent.robot.pose.raw_pose[0].numpy()[:3]
        return torch.tensor([[*(np.asarray(xyz) - root), *self._rot, gripper]], dtype=torch.float32)

    def geometry(self) -> dict:
        """The rest pose's fingertip geometry in the world: the finger frame's x / y axes and the tip's bottom below
        the TCP (the gripper pointing down, closed)."""
        a = self.ms.unwrapped.agent
        from scipy.spatial.transform import Rotation

        f1 = a.finger1_link.pose.raw_pose[0].numpy()
        rf = Rotation.from_quat(_xyzw(f1[3:]))
        tcp = a.tcp.pose.raw_pose[0].numpy()
        bottom = f1[:3] + rf.apply(TIP_CENTER + np.array([0.0, 0.0, TIP_HALF[2]]))
        return {"x": rf.apply([1.0, 0.0, 0.0]), "y": rf.apply([0.0, 1.0, 0.0]), "tip_below_tcp": tcp[2] - bottom[2]}

    def run(self, start, targets, gripper_start: float = -1.0, settle: int = 40) -> dict:
        """Put the cube at :data:`CUBE_AT`, drive ManiSkill's arm to ``start`` (xyz, gripper ``gripper_start``) for
        ``settle`` steps, then step both simulators through ``targets`` (a list of (xyz, gripper)) from ManiSkill's
        state: ``{"physx": [reading, ...], "newton": [...]}``."""
        import torch
        from scipy.spatial.transform import Rotation

        ms, base = self.ms, self.ms.unwrapped
        ms.reset(seed=0)
        state = base.get_state_dict()
        state["actors"]["cube"][0] = torch.tensor([*CUBE_AT, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
        state["actors"]["goal_site"][0, :3] = torch.tensor([0.0, 0.3, 0.3])
        base.set_state_dict(state)
        base.agent.controller.reset()
        tcp = base.agent.tcp.pose.raw_pose[0].numpy()
        self._rot = Rotation.from_quat(_xyzw(tcp[3:])).as_rotvec()  # the rest pose's orientation, kept
        for _ in range(settle):
            ms.step(self._action(start, gripper_start))
        state = base.get_state_dict()
        out = {"physx": [], "newton": []}
        for xyz, g in targets:
            ms.step(self._action(xyz, g))
            out["physx"].append(reading(_maniskill_raw(base)))
        env = self.newton
        env.set_state_dict({g: dict(d) for g, d in state.items() if g in ("actors", "articulations")})
        for xyz, g in targets:
            env.step(self._action(xyz, g))
            out["newton"].append(reading(_newton_raw(env)))
        return out

    # -- the probes ---------------------------------------------------------------------------------------------

    def press(self, where: str, overlap: float = 0.002, depth: float = 0.025, steps: int = 40) -> dict:
        """The closed fingertips pressed down on the cube's top ``where`` ("face": both tips on its centre; "edge":
        both tips over one edge, ``overlap`` [m] onto the top face; "corner": the tips moved along that edge until the
        right one (``panda_rightfinger``) sits over a corner, about ``overlap`` onto the top both ways, the left one
        beside it over the edge) by a TCP target ramped from 4 mm above the touch to ``depth`` below it over the first
        three quarters of ``steps`` and then held: the force rises with the arm's drive error, and the tips' friction
        drags the cube along the table by the arm's give (10-12 mm on both simulators)."""
        if where not in ("face", "edge", "corner"):
            raise ValueError(f"press: where expected 'face', 'edge' or 'corner', got {where!r}")
        g = self.geometry()
        inward = CUBE_HALF + TIP_HALF[0] - overlap
        xy = CUBE_AT[:2].copy()
        if where in ("edge", "corner"):
            xy -= inward * g["x"][:2]
        if where == "corner":
            xy -= (CUBE_HALF - overlap) * g["y"][:2]
        z0 = 2 * CUBE_HALF + g["tip_below_tcp"] + 0.004
        ramp = [min(1.0, k / (0.75 * steps)) for k in range(1, steps + 1)]
        return self.run([*xy, z0], [([*xy, z0 - depth * r], -1.0) for r in ramp])

    def close_on_top(self, opening: float = 0.004, depth: float = 0.015, press: int = 20, close: int = 15) -> dict:
        """The fingertips, each ``opening`` [m] from the TCP (both on the cube's top face), pressed down on its centre
        by a TCP target ramped ``depth`` below the touch over ``press`` steps, then the gripper closed for ``close``
        steps with the target held: the tips slide inward over the face, the face's friction pushing them apart."""
        g = self.geometry()
        xy = CUBE_AT[:2]
        z0 = 2 * CUBE_HALF + g["tip_below_tcp"] + 0.004
        half_open = 2.0 * (opening + 0.01) / 0.05 - 1.0  # the gripper's pd_joint_pos range [-0.01, 0.04] m
        targets = [([*xy, z0 - (depth + 0.004) * k / press], half_open) for k in range(1, press + 1)]
        targets += [(targets[-1][0], -1.0)] * close
        return self.run([*xy, z0], targets, gripper_start=half_open)

    def hold(self, lift: float = 0.1, lift_steps: int = 4, still: int = 10, grip_steps: int = 10) -> dict:
        """The open gripper lowered around the cube's centre (the TCP 5 mm below the cube's top), closed for
        ``grip_steps``, lifted ``lift`` [m] in ``lift_steps`` (the drives' fastest), moved as fast sideways and back,
        then held ``still``: where the cube sits in the fingers along the way."""
        xy, z = CUBE_AT[:2], 2 * CUBE_HALF - 0.005
        targets = [([*xy, z], -1.0)] * grip_steps
        for k in range(1, lift_steps + 1):
            targets.append(([*xy, z + lift * k / lift_steps], -1.0))
        top = z + lift
        for dy in (0.05, 0.1, 0.05, 0.0):
            targets.append(([xy[0], xy[1] + dy, top], -1.0))
        targets += [([*xy, top], -1.0)] * still
        return self.run([*xy, z], targets, gripper_start=1.0)

    def push(self, height: float, distance: float = 0.06, steps: int = 12) -> dict:
        """The closed fingertips pushed along +x (the finger frame's axis across the pad) into the cube's side, the
        tips' bottom ``height`` [m] above the table, the TCP target moved ``distance`` past the touch in ``steps``."""
        g = self.geometry()
        z = height + g["tip_below_tcp"]
        x0 = CUBE_AT[0] - CUBE_HALF - TIP_HALF[0] - 0.004
        targets = [([x0 + (distance + 0.004) * k / steps, CUBE_AT[1], z], -1.0) for k in range(1, steps + 1)]
        targets += [targets[-1]] * 8
        return self.run([x0, CUBE_AT[1], z], targets)


def _row(readings, keys=("force", "depth", "reach", "tilt_deg")) -> str:
    scale = {"force": 1.0, "depth": 1e3, "reach": 1e3, "tilt_deg": 1.0}
    return " ".join("/".join(f"{r[k] * scale[k]:.1f}" for k in keys) for r in readings)


def main() -> None:  # pragma: no cover - the docs table's source
    warnings.filterwarnings("ignore")
    probe = Probe()
    for where in ("face", "edge", "corner"):
        out = probe.press(where)
        for side in ("physx", "newton"):
            print(f"press {where:6s} {side:6s} force/depth mm/reach mm/tilt:", _row(out[side][8:40:6]))
    for overlap in (0.001, 0.002, 0.003):
        out = probe.press("corner", overlap=overlap, depth=0.045)
        for side in ("physx", "newton"):
            print(f"corner {overlap * 1e3:.0f} mm {side:6s}:", _row(out[side][6:40:3]))
    out = probe.hold()
    for side in ("physx", "newton"):
        print(f"hold {side:6s} cube in TCP frame [mm]:", " ".join(
            "/".join(f"{v * 1e3:.1f}" for v in r["cube_in_tcp"]) for r in out[side][9::2]))  # fmt: skip
    for h in (0.005, 0.015, 0.025):
        out = probe.push(h)
        for side in ("physx", "newton"):
            r = out[side][-1]
            print(f"push at {h * 1e3:.0f} mm {side:6s}: cube moved {1e3 * (r['cube'][0] - CUBE_AT[0]):.1f} mm, "
                  f"tilt {r['tilt_deg']:.1f} deg, max force {max(x['force'] for x in out[side]):.1f} N")  # fmt: skip


if __name__ == "__main__":  # pragma: no cover
    main()
