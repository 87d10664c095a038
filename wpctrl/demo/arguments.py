"""The demo's command-line options and every check on them, before anything heavy is imported: the solvers and
actuations it offers, the combinations that hold the Panda at ManiSkill's gains (and why the others do not), the extras
it needs."""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys

from ..extras import install_hint
from ..tasks.names import CONTROL_MODES as MANISKILL_PANDA_MODES

SOLVERS = ("mujoco", "steel", "kamino", "featherstone", "semi_implicit", "xpbd")
"""Newton's articulation solvers the demo knows; :func:`unsupported` says which of them cannot hold the Panda."""
MAXIMAL_SOLVERS = ("xpbd", "semi_implicit")  # body-coordinate solvers: joint_q is recovered with eval_ik each step
PANDA_MODES = MANISKILL_PANDA_MODES + ("osc_ee_delta_pose", "osc_ee_pose", "joint_impedance_delta_pos")
"""wpctrl.robots.PANDA_CONTROL_MODES' names: ManiSkill's (the light list of :mod:`wpctrl.tasks.names`) and wpctrl's
torque-level ones, so that --help and argument errors need no heavy import (a test keeps the two equal)."""
ROBOT_MODES = {
    "panda": PANDA_MODES,
    "fetch": (
        "pd_joint_delta_pos",
        "pd_joint_pos",
        "pd_ee_delta_pos",
        "pd_ee_delta_pose",
        "pd_joint_target_delta_pos",
        "pd_ee_target_delta_pos",
        "pd_ee_target_delta_pose",
        "pd_joint_vel",
        "pd_joint_delta_pos_vel",
        "pd_joint_delta_pos_stiff_body",
        "osc_ee_delta_pose",
        "osc_ee_pose",
        "joint_impedance_delta_pos",
    ),
    "allegro_hand_right": ("pd_joint_delta_pos", "pd_joint_pos", "pd_joint_target_delta_pos"),
    "unitree_g1_simplified_legs": ("pd_joint_pos", "pd_joint_delta_pos"),
}
"""The robots ``--robot`` offers and their control modes: the built-in Panda, and ManiSkill agents loaded with
:func:`wpctrl.maniskill.load_robot` (their modes as ManiSkill names them, less those in :data:`ROBOT_MODES_REFUSED`,
and the impedance modes ``load_robot`` adds for an arm; a test keeps the two tables equal to ``load_robot``'s)."""
ROBOT_MODES_REFUSED = {
    ("fetch", "pd_ee_delta_pose_align"): "its frame 'ee_align' is not implemented in ManiSkill 3.0.1 either",
    ("fetch", "pd_joint_pos_vel"): (
        "it normalises actions over the unlimited roll joints, where ManiSkill's own targets are NaN"
    ),
}
"""Modes a ManiSkill agent defines that ManiSkill itself cannot run (wpctrl refuses them too), with the reason."""
EXPLICIT_PDS = ("coupled", "stable", "naive")  # build_controller's explicit_pd laws (a test keeps them equal)
ACTUATIONS = ("implicit", "explicit")
DEFAULT_OUT = "wpctrl-demo"  # git-ignored in this repository
STABLE_MIN_SIM_FREQ = 500  # [Hz] stable explicit PD tracks the Panda's 1000/100 gains from here (measured)
FEATHERSTONE_MIN_SIM_FREQ = 1000  # [Hz] Featherstone's penalty joint limits hold the fingers from here (measured)
SCORE_AFTER_S = 0.5  # [s] an env's tracking is scored from this long after it (re)started at rest
SOLVER_LABELS = {
    "mujoco": "MuJoCo-Warp",
    "steel": "Newton's Steel",
    "kamino": "Newton's Kamino",
    "featherstone": "Newton's Featherstone",
    "semi_implicit": "Newton's semi-implicit",
    "xpbd": "Newton's XPBD",
}


COMPILE_ESTIMATE = "about 1.5 min on a 2-core CPU, 1 min on a GPU"


def compile_what(args) -> str:
    """What the compile notice says is being compiled."""
    return (
        f"Warp kernels for {args.device}: wpctrl's {args.control_mode} step for {args.robot} and "
        f"{SOLVER_LABELS[args.solver]}"
    )


def explicit_pd_choices() -> tuple[str, ...]:
    """build_controller's explicit PD laws (``explicit_pd=...``), the demo's default first."""
    return EXPLICIT_PDS


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the description's line breaks; widens the option column so each help starts on the option's line."""

    def __init__(self, prog):
        super().__init__(prog, max_help_position=30, width=118)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="wpctrl demo",
        description=__doc__.split("\n\n")[0],
        epilog="control modes (--control-mode) by robot (--robot):\n"
        + "\n".join(f"  {robot}: {', '.join(modes)}" for robot, modes in ROBOT_MODES.items())
        + "\n\nManiSkill's tasks: wpctrl demo --task PushCube-v1|PickCube-v1 [--envs N] [--device D] [--out DIR]"
        " (wpctrl demo --task PickCube-v1 --help lists its options)",
        formatter_class=_HelpFormatter,
    )
    p.add_argument(
        "--robot",
        default="panda",
        choices=tuple(ROBOT_MODES),
        help="panda (built in), or a ManiSkill agent loaded by uid (needs the [maniskill] extra) (default panda)",
    )
    p.add_argument("--envs", type=int, default=16, help="parallel envs (robots); per rank under torchrun (default 16)")
    p.add_argument(
        "--device", default="cpu", help="cpu | cuda | cuda:N; under torchrun 'cuda' = cuda:LOCAL_RANK (default cpu)"
    )
    p.add_argument(
        "--control-mode",
        default="pd_joint_delta_pos",
        metavar="MODE",
        help="one of the robot's ManiSkill control modes, listed below (default pd_joint_delta_pos)",
    )
    p.add_argument(
        "--actuation",
        default="implicit",
        choices=ACTUATIONS,
        help="implicit: the solver's own PD drive; explicit: wpctrl's PD torques in joint_f (default implicit)",
    )
    p.add_argument(
        "--explicit-pd",
        default=None,
        choices=EXPLICIT_PDS,
        help="the PD law with --actuation explicit: coupled (PhysX's coupled implicit drive, 100 Hz; the default) | "
        f"stable (per-joint response, {STABLE_MIN_SIM_FREQ} Hz) | naive (refused: does not hold the Panda's gains)",
    )
    p.add_argument(
        "--solver",
        default="mujoco",
        choices=SOLVERS,
        help="Newton solver: mujoco (MuJoCo-Warp), steel or kamino hold ManiSkill's 1000/100 Panda gains at 100 Hz; "
        f"featherstone with --actuation explicit at {FEATHERSTONE_MIN_SIM_FREQ} Hz; semi_implicit and xpbd are "
        "refused with the reason (default mujoco)",
    )
    p.add_argument("--seconds", type=float, default=4.0, help="simulated time [s] (default 4)")
    p.add_argument(
        "--sim-freq",
        type=int,
        default=None,
        help=f"solver steps per second [Hz] (default 100; {STABLE_MIN_SIM_FREQ} with --explicit-pd stable, "
        f"{FEATHERSTONE_MIN_SIM_FREQ} with featherstone)",
    )
    p.add_argument("--control-freq", type=int, default=20, help="control steps per second [Hz] (default 20)")
    p.add_argument("--seed", type=int, default=0, help="run seed; each torchrun rank derives its own (default 0)")
    p.add_argument(
        "--out", default=DEFAULT_OUT, help=f"folder for summary.json and tracking.png (default {DEFAULT_OUT})"
    )
    p.add_argument(
        "--graph", action=argparse.BooleanOptionalAction, default=True, help="capture the control step (default on)"
    )
    p.add_argument(
        "--progress", action=argparse.BooleanOptionalAction, default=True, help="tqdm progress bar (default on)"
    )
    from ..console import add_output_options

    add_output_options(p)
    return p


def _fail(parser: argparse.ArgumentParser, msg: str):
    parser.print_usage(sys.stderr)
    print(f"wpctrl demo: error: {msg}", file=sys.stderr)
    raise SystemExit(2)


DEFAULT_EXPLICIT_PD = "coupled"
"""The demo's explicit PD law: PhysX's coupled implicit drive holds the Panda at 100 Hz (arm RMS 0.034 rad)."""


def default_sim_freq(solver: str, actuation: str, explicit_pd: str | None = None) -> int:
    """The demo's solver rate [Hz] for a combination: the lowest rate measured to track the Panda at its gains."""
    if solver == "featherstone":
        return FEATHERSTONE_MIN_SIM_FREQ
    if actuation == "explicit" and (explicit_pd or DEFAULT_EXPLICIT_PD) == "stable":
        return STABLE_MIN_SIM_FREQ
    return 100


def unsupported(solver: str, actuation: str, explicit_pd: str | None, sim_freq: int) -> str | None:
    """Why a combination cannot hold the Panda at ManiSkill's gains (1000/100), or None when it can.

    Measured on the CPU with Newton 1.8 and MuJoCo-Warp 3.17 (this demo, 4-16 envs, 2-4 s). Arm RMS error against
    the desired trajectory: MuJoCo implicit 100 Hz 0.029 rad; Steel and Kamino implicit 100 Hz 0.034; coupled
    explicit PD (PhysX's drive) 0.034 at 100 Hz with MuJoCo, Steel and Kamino; stable explicit PD with MuJoCo 0.113
    (100 Hz, chatter at the control rate), 0.047 (200 Hz), 0.034 (500 Hz), 0.032 (1 kHz), with Kamino 0.037 (500 Hz);
    with Featherstone 0.032 (1 kHz), NaN at 100 Hz. Semi-implicit and XPBD go non-finite.
    """
    if solver == "semi_implicit":
        return (
            "--solver semi_implicit: Newton's semi-implicit (symplectic Euler) solver holds the joints with penalty "
            "springs (ke 1e4) that the Panda's 1000/100 drive gains overpower (NaN within 0.1 s at 100 Hz and within "
            "0.05 s at 1 kHz, implicit or explicit); use --solver mujoco, steel or kamino"
        )
    if solver == "xpbd":
        return (
            "--solver xpbd: Newton 1.8's XPBD goes non-finite on the Panda once its gripper fingers are driven at "
            "ManiSkill's gains (NaN within 0.3 s at 100 Hz and 1 kHz, 4-16 iterations, implicit or explicit); use "
            "--solver mujoco, or featherstone with --actuation explicit"
        )
    if actuation == "implicit" and solver == "featherstone":
        return (
            "--solver featherstone --actuation implicit: Featherstone's built-in joint drive is an explicit PD and "
            "diverges at the Panda's 1000/100 gains (NaN within 0.05 s at 100 Hz); use --actuation explicit "
            "(coupled PD, the default) or --solver mujoco"
        )
    if actuation == "explicit" and explicit_pd == "naive":
        return (
            "--explicit-pd naive: the textbook explicit PD does not hold the Panda's 1000/100 gains (NaN within 0.1 s "
            "at 100 Hz; at 1 kHz finite but 0.8 rad RMS arm error: the 15 g fingers need a step under 2 m / Kd = "
            "0.3 ms); use --explicit-pd coupled (the default) or --actuation implicit"
        )
    if solver == "featherstone" and sim_freq < FEATHERSTONE_MIN_SIM_FREQ:
        return (
            f"--solver featherstone at --sim-freq {sim_freq}: Featherstone's joint limits are explicit penalty springs "
            f"(ke 1e4, kd 10) that the 15 g fingers hit when the gripper closes (NaN within 0.25 s at 100 Hz); use "
            f"--sim-freq {FEATHERSTONE_MIN_SIM_FREQ} (its default) or more, or --solver mujoco"
        )
    if actuation == "explicit" and explicit_pd == "stable" and sim_freq < STABLE_MIN_SIM_FREQ:
        return (
            f"--explicit-pd stable at --sim-freq {sim_freq}: stable PD uses each joint's own response only, and "
            f"below {STABLE_MIN_SIM_FREQ} Hz the coupled arm chatters at the control rate (arm RMS 0.11 rad at 100 "
            f"Hz vs 0.034 at 500 Hz); use --sim-freq {STABLE_MIN_SIM_FREQ} (its default) or more, --explicit-pd "
            "coupled (100 Hz), or --actuation implicit"
        )
    return None


def supported_combinations() -> str:
    """One line: what holds the Panda, at the demo's defaults."""
    return (
        f"MuJoCo, Steel and Kamino with --actuation implicit or explicit (coupled PD) at 100 Hz (--explicit-pd stable "
        f"at --sim-freq {STABLE_MIN_SIM_FREQ}), and Featherstone with --actuation explicit at --sim-freq "
        f"{FEATHERSTONE_MIN_SIM_FREQ}, hold ManiSkill's Panda gains"
    )


def _check_args(parser, args) -> None:
    """Every argument check, before anything is built or compiled (warp is imported for the device check only)."""
    if args.envs < 1:
        _fail(parser, f"--envs: expected >= 1, got {args.envs}")
    modes = ROBOT_MODES[args.robot]
    refused = ROBOT_MODES_REFUSED.get((args.robot, args.control_mode))
    if refused:
        _fail(parser, f"--robot {args.robot} --control-mode {args.control_mode}: refused, {refused}")
    if args.control_mode not in modes:
        _fail(
            parser,
            f"--control-mode: expected one of {', '.join(modes)} for --robot {args.robot}, got {args.control_mode!r}",
        )
    if args.robot != "panda" and args.solver != "mujoco":
        _fail(
            parser,
            f"--robot {args.robot} --solver {args.solver}: the demo runs ManiSkill's robots with --solver mujoco only "
            "(their modes keep ManiSkill's balance_passive_force, which only MuJoCo's per-body gravity compensation "
            "honours, and floating robots stand on a ground plane through MuJoCo's contacts); use --solver mujoco",
        )
    if args.control_freq < 1:
        _fail(parser, f"--control-freq: expected a positive number of steps per second, got {args.control_freq}")
    shortest = SCORE_AFTER_S + 1.0 / args.control_freq
    if not (math.isfinite(args.seconds) and args.seconds >= shortest - 1e-9):
        _fail(
            parser,
            f"--seconds: expected at least {shortest:g} s (tracking is scored from {SCORE_AFTER_S:g} s after an env "
            f"starts, and one control step at --control-freq {args.control_freq} is {1.0 / args.control_freq:g} s), "
            f"got {args.seconds:g}",
        )
    if args.actuation == "explicit" and args.explicit_pd is None:
        args.explicit_pd = DEFAULT_EXPLICIT_PD
    if args.sim_freq is None:
        args.sim_freq = default_sim_freq(args.solver, args.actuation, args.explicit_pd)
    if args.sim_freq < 1 or args.sim_freq % args.control_freq:
        _fail(
            parser,
            f"--sim-freq must be a positive multiple of --control-freq, got {args.sim_freq} and {args.control_freq}",
        )
    if args.actuation == "implicit" and args.explicit_pd is not None:
        _fail(parser, f"--explicit-pd {args.explicit_pd}: applies to --actuation explicit only")
    why = unsupported(args.solver, args.actuation, args.explicit_pd, args.sim_freq)
    if why:
        _fail(parser, why)
    if args.device != "cpu":
        if not (args.device == "cuda" or args.device.startswith("cuda:")):
            _fail(parser, f"--device: expected cpu, cuda or cuda:N, got {args.device!r}")
        from ..console import cuda_absent, quiet_warp

        if cuda_absent():  # known without importing Warp
            _fail(parser, f"--device {args.device}: no CUDA device is available on this machine")
        import warp as wp

        with quiet_warp(args.verbose):
            cuda = wp.is_cuda_available()
        if not cuda:
            _fail(parser, f"--device {args.device}: no CUDA device is available on this machine")
        if args.device != "cuda":  # 'cuda' means cuda:LOCAL_RANK under torchrun, checked when the rank starts
            from ..config import ConfigError
            from ..devices import check_device

            try:
                check_device(args.device, "--device")
            except ConfigError as e:
                _fail(parser, str(e))


def _check_extras(args) -> None:
    """A one-line error naming the extra to install, before anything is built (the base install lacks them)."""
    needed = [("matplotlib", "matplotlib")]
    if args.robot != "panda":
        needed.append(("mani_skill", "ManiSkill"))
    if args.progress:
        needed.append(("tqdm", "tqdm"))
    if args.solver == "mujoco":
        needed += [("mujoco", "MuJoCo"), ("mujoco_warp", "MuJoCo-Warp")]
    missing = []
    for module, label in needed:
        try:  # found without importing it (matplotlib and MuJoCo-Warp take seconds to import)
            found = importlib.util.find_spec(module) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            missing.append(label)
    if missing:
        extra = "demo,maniskill" if "ManiSkill" in missing else "demo"
        for_what = f"--robot {args.robot} needs" if missing == ["ManiSkill"] else "the demo needs"
        print(
            f"wpctrl demo: error: {', '.join(missing)} not installed; {for_what} the [{extra}] extra: "
            + install_hint(extra),
            file=sys.stderr,
        )
        raise SystemExit(2)
