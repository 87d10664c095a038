"""How a task's control step runs its MuJoCo-Warp steps: written out one after another, or as loops on the device.

A control step of the tasks is K = 5 physics steps of ``TaskPhysics.substeps`` MuJoCo-Warp steps each: 80 solver steps
at the default 16 substeps, 40 at 8. Captured written out (``"unrolled"``), the step's CUDA graph holds every one of
them, a few hundred kernel nodes each, and launching a graph costs the host time in proportion to its nodes: at 4,096
envs and 8 substeps the launch took the host about as long as the GPU took to run it, so nothing else (the policy,
the next launch) could overlap it.

``"device"`` runs each physics step's solver steps as a loop on the GPU (a CUDA conditional ``while`` node,
:func:`warp.capture_while`): the graph holds two solver steps per physics step (the state pair's two directions) and
a counter, plus the last pair of the control step, which also hands the contacts to the sensor. The same kernels run
in the same order on the same arrays: the result is the written-out step's. The controller's per-physics-step work
(``before_simulation_step``) stays written out, so the controller counts its physics steps as before.

Conditional nodes need CUDA 12.4+ (driver and toolkit). On the CPU, and on CUDA without a captured graph, Warp runs
the same loop from the host (reading the counter back each iteration on CUDA): correct, not faster.
"""

from __future__ import annotations

from collections.abc import Callable

import warp as wp

from ..config import ConfigError

__all__ = ["SUBSTEP_LOOPS", "repeat", "resolve_substep_loop"]

SUBSTEP_LOOPS = ("auto", "unrolled", "device")
"""``substep_loop`` values of :func:`wpctrl.tasks.make`: ``"auto"`` is ``"device"`` where it shortens a captured
CUDA graph (CUDA with conditional nodes, graph capture on, an even number of substeps), else ``"unrolled"``."""


def resolve_substep_loop(loop: str, device: wp.Device, graph: bool, substeps: int) -> str:
    """``loop`` (one of :data:`SUBSTEP_LOOPS`) for these settings: ``"unrolled"`` or ``"device"``; a ``"device"``
    loop that cannot run here is refused, naming why."""
    if loop not in SUBSTEP_LOOPS:
        raise ConfigError(f"make: substep_loop expected one of {SUBSTEP_LOOPS}, got {loop!r}")
    even = substeps >= 2 and substeps % 2 == 0
    conditional = device.is_cuda and graph and wp.is_conditional_graph_supported()
    if loop == "auto":
        return "device" if conditional and even else "unrolled"
    if loop == "device":
        if not even:
            raise ConfigError(f"make: substep_loop='device' steps the state pair in both directions per iteration: "
                              f"expected an even TaskPhysics.substeps >= 2, got {substeps}")  # fmt: skip
        if device.is_cuda and graph and not wp.is_conditional_graph_supported():
            raise ConfigError("make: substep_loop='device' in a captured CUDA graph needs conditional graph nodes "
                              "(CUDA driver and toolkit 12.4+), which this installation lacks; use "
                              "'unrolled'")  # fmt: skip
    return loop


@wp.kernel
def _set_count(count: wp.array[wp.int32], n: int):
    count[0] = n


@wp.kernel
def _count_down(count: wp.array[wp.int32]):
    count[0] = count[0] - 1


def repeat(count: wp.array, n: int, body: Callable[[], None]) -> None:
    """``body`` (launches only) ``n`` times as a device loop counted down in ``count`` (a (1,) int32 array of the
    device); ``n`` <= 1 writes the body out (or nothing)."""
    if n <= 0:
        return
    if n == 1:
        body()
        return
    wp.launch(_set_count, dim=1, inputs=[count, n], device=count.device)

    def iteration():
        body()
        wp.launch(_count_down, dim=1, inputs=[count], device=count.device)

    wp.capture_while(count, iteration)
