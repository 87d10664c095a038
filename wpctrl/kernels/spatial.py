"""Warp functions and constants shared by the articulation-inertia kernels (:mod:`.inertia`, :mod:`.inertia_unrolled`,
:mod:`.coupled_drive`)."""

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
    R = wp.quat_to_matrix(wp.transform_get_rotation(Xb))
    cw = R * body_com[b] + wp.transform_get_translation(Xb)  # the COM in world, with the rotation matrix needed below
    c = wp.vec3d(wp.float64(cw[0]), wp.float64(cw[1]), wp.float64(cw[2]))
    RI = R * body_inertia[b]
    # R I R^T, symmetric: its upper triangle, mirrored
    i00 = wp.float64(wp.dot(RI[0], R[0]))
    i01 = wp.float64(wp.dot(RI[0], R[1]))
    i02 = wp.float64(wp.dot(RI[0], R[2]))
    i11 = wp.float64(wp.dot(RI[1], R[1]))
    i12 = wp.float64(wp.dot(RI[1], R[2]))
    i22 = wp.float64(wp.dot(RI[2], R[2]))
    Iw = wp.mat33d(i00, i01, i02, i01, i11, i12, i02, i12, i22)
    return m, c, Iw
