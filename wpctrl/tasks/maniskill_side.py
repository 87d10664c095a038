"""The real ManiSkill's table-top tasks on its CPU PhysX without a rendering device.

ManiSkill builds visual shapes and render materials for every actor and robot link, and those need a rendering
device. :func:`no_visuals` skips exactly that side while an env is built: the actor builders' ``add_*_visual*``
calls, the URDF loader's link visuals, the MJCF loader's visual bodies and the render materials and textures.
Physics, collision shapes, physical materials, controllers, observations, rewards and evaluation stay ManiSkill's own.
:func:`make_maniskill` builds one env that way (``sim_backend="physx_cpu"``, ``render_backend="none"``, one env).

Needs the ``maniskill`` extra (mani-skill 3.0.1); nothing here is imported by ``wpctrl.tasks`` itself.
"""

from __future__ import annotations

import contextlib
import warnings

__all__ = ["make_maniskill", "no_visual_loaders", "no_visuals"]

_VISUAL_METHODS = ("add_plane_visual", "add_box_visual", "add_capsule_visual", "add_cylinder_visual",
                   "add_sphere_visual", "add_visual_from_file")  # fmt: skip


class _Inert:
    """Stands in for a render material or texture: accepts any arguments and attributes, renders nothing."""

    def __init__(self, *args, **kwargs):
        pass

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


@contextlib.contextmanager
def no_visual_loaders():
    """ManiSkill's URDF / MJCF loaders without visual shapes or render materials, for the duration."""
    from mani_skill.utils.building import _mjcf_loader
    from mani_skill.utils.building.urdf_loader import URDFLoader

    original_build_link = URDFLoader._build_link
    original_mjcf_init = _mjcf_loader.MJCFLoader.__init__
    originals = {n: getattr(_mjcf_loader, n) for n in ("RenderMaterial", "RenderTexture2D")}

    def build_link(self, link, *args, **kwargs):
        visuals = link.visuals
        link.visuals = []
        try:
            return original_build_link(self, link, *args, **kwargs)
        finally:
            link.visuals = visuals

    def mjcf_init(self, *args, **kwargs):
        original_mjcf_init(self, *args, **kwargs)
        self.visual_groups = []

    URDFLoader._build_link = build_link
    _mjcf_loader.MJCFLoader.__init__ = mjcf_init
    for n in originals:
        setattr(_mjcf_loader, n, _Inert)
    try:
        yield
    finally:
        URDFLoader._build_link = original_build_link
        _mjcf_loader.MJCFLoader.__init__ = original_mjcf_init
        for n, v in originals.items():
            setattr(_mjcf_loader, n, v)


@contextlib.contextmanager
def no_visuals():
    """ManiSkill without visual shapes or render materials (actors, URDF and MJCF loaders), for the duration."""
    import sapien
    from sapien.wrapper.actor_builder import ActorBuilder

    originals = {n: getattr(ActorBuilder, n) for n in _VISUAL_METHODS}
    render = {n: getattr(sapien.render, n) for n in ("RenderMaterial", "RenderTexture2D")}

    def skip(self, *args, **kwargs):
        return self

    for n in _VISUAL_METHODS:
        setattr(ActorBuilder, n, skip)
    for n in render:
        setattr(sapien.render, n, _Inert)
    try:
        with no_visual_loaders():
            yield
    finally:
        for n, v in originals.items():
            setattr(ActorBuilder, n, v)
        for n, v in render.items():
            setattr(sapien.render, n, v)


def make_maniskill(env_id: str, control_mode: str, **kwargs):
    """The real ManiSkill env (``gym.make``: PhysX CPU, one env, ``obs_mode="state"``, rendering stubbed out), reset
    once with seed 0. ``kwargs`` go to ``gym.make`` (e.g. ``reward_mode``, ``robot_init_qpos_noise``, ``robot_uids``:
    without it, the task's default robot, as :func:`wpctrl.tasks.make`'s)."""
    try:
        import gymnasium as gym
        import mani_skill.envs  # noqa: F401  (registers the tasks)
    except ImportError as e:
        from ..extras import missing

        raise ImportError(missing("the real ManiSkill side", "maniskill", e, torch=True)) from e

    with warnings.catch_warnings(), no_visuals():
        warnings.simplefilter("ignore")
        env = gym.make(env_id, sim_backend="physx_cpu", render_backend="none", num_envs=1, obs_mode="state",
                       control_mode=control_mode, **kwargs)  # fmt: skip
        env.reset(seed=0)
    return env
