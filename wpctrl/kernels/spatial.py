"""Warp functions and constants shared by the articulation-inertia kernels (:mod:`.inertia`, :mod:`.inertia_unrolled`,
:mod:`.drive`)."""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

J_FIXED = 0
J_REVOLUTE = 1
J_PRISMATIC = 2

_FLOAT32_EPS = float(np.finfo(np.float32).eps)


@wp.func
def _body_world_inertia(
    Xb: wp.transform,
    b: int,
    body_mass: wp.array[float],
    body_com: wp.array[wp.vec3],
    body_inertia: wp.array[wp.mat33],
):
    """Body ``b`` at world pose ``Xb``: its mass [kg], world COM [m] and world inertia about its COM [kg m^2], float64
    (the inertia rotated in float32, as Newton stores it)."""
    m = wp.float64(body_mass[b])
    cw = wp.transform_point(Xb, body_com[b])
    c = wp.vec3d(wp.float64(cw[0]), wp.float64(cw[1]), wp.float64(cw[2]))
    R = wp.quat_to_matrix(wp.transform_get_rotation(Xb))
    Iw32 = R * body_inertia[b] * wp.transpose(R)
    Iw = wp.mat33d(
        wp.float64(Iw32[0, 0]), wp.float64(Iw32[0, 1]), wp.float64(Iw32[0, 2]),
        wp.float64(Iw32[1, 0]), wp.float64(Iw32[1, 1]), wp.float64(Iw32[1, 2]),
        wp.float64(Iw32[2, 0]), wp.float64(Iw32[2, 1]), wp.float64(Iw32[2, 2]),
    )  # fmt: skip
    return m, c, Iw
