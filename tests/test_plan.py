"""The engine's plan is host-only data: built from configs and a binding without touching a device, printable, and
it decides which parts a mode runs."""

from __future__ import annotations

import numpy as np

import wpctrl
from wpctrl.binding import JointBinding
from wpctrl.config import config_rows
from wpctrl.config.rows import Rows
from wpctrl.engine.plan import Options, make_plan


def _binding(names, num_envs=3, stride=9) -> JointBinding:
    n = len(names)
    e = np.arange(num_envs)[:, None]
    idx = (np.arange(n)[None, :] + e * stride).astype(np.int32)
    return JointBinding(
        joint_names=list(names),
        num_envs=num_envs,
        joint_index=idx,
        coord_index=idx,
        dof_index=idx,
        q_base=idx[:, 0].copy(),
        qd_base=idx[:, 0].copy(),
        q_off=np.arange(n, dtype=np.int32),
        qd_off=np.arange(n, dtype=np.int32),
        qlimits=np.tile(np.array([[-2.0, 2.0]], np.float32), (n, 1)),
    )


def test_plan_needs_no_device_and_picks_the_parts():
    names = [f"j{i}" for i in range(4)]
    arm = wpctrl.PDJointPosControllerConfig(names[:3], -0.1, 0.1, 100.0, 10.0, use_delta=True,
                                            actuator=wpctrl.DCMotor(50.0, 3.0))  # fmt: skip
    grip = wpctrl.JointEffortControllerConfig(names[3:], -5.0, 5.0)
    b = _binding(names)
    rows = Rows.concat([config_rows(arm, b.qlimits[:3]), config_rows(grip, b.qlimits[3:])])
    plan = make_plan(
        rows,
        b,
        Options(
            num_substeps=5,
            actuation=wpctrl.Actuation("explicit"),
            delay=wpctrl.Delay((0, 2)),
            diagnostics=wpctrl.Diagnostics(track_effort=True),
        ),
    )
    assert plan.parts == ("drive_properties", "effort_command", "actuator_models", "delay", "effort_readout")
    assert plan.per_substep and plan.writes_joint_f and plan.strided and plan.q_stride == 9
    assert plan.layout.act_model == (1, 1, 1, 0) and plan.layout.kind[3] == wpctrl.config.ROW_EFFORT
    text = str(plan)
    assert "3 envs x 4 rows" in text and "DC motor" in text and "effort" in text
    # implicit, nothing per substep: the substep launch is elided and only the drive part is on
    arm2 = wpctrl.PDJointPosControllerConfig(names, -0.1, 0.1, 100.0, 10.0, use_delta=True)
    plan2 = make_plan(config_rows(arm2, b.qlimits), b, Options(num_substeps=5))
    assert plan2.parts == ("drive_properties",) and not plan2.per_substep
