"""Video of evaluation episodes (``python -m wpctrl evaluate --sim newton --video FILE``): env 0 of the Newton env,
rendered after every control step by MuJoCo's offscreen renderer (``mujoco.Renderer``) from the MuJoCo model Newton's
solver built (its ``mj_model``, the state copied from MuJoCo-Warp's world 0), through the task's ManiSkill human-render
camera (:func:`camera`: eye ``(0.6, 0.7, 0.6)`` looking at ``(0, 0, 0.35)`` for most tasks), the goal drawn as a green
sphere where the task has a goal marker (a visual actor, not part of the physics model; StackCube-v1 and
LiftPegUpright-v1 have none); written with imageio at the control rate (20 fps).

Headless: without ``DISPLAY`` the renderer's OpenGL context is EGL (``MUJOCO_GL=egl``, unless set: ``osmesa`` also
works where Mesa's OSMesa is installed); Mesa's software EGL driver renders without a GPU. Where no context can be
made, or imageio is missing, :func:`unavailable` says why in one line and the evaluation runs without the video.
"""

from __future__ import annotations

import math
import os
import sys

__all__ = ["FPS", "MAX_EPISODES", "Recorder", "camera", "open_recorder", "unavailable"]

FPS = 20
"""Frames per second: the tasks' control rate, so the video runs in real time."""
WIDTH, HEIGHT = 512, 384
"""Frame size (multiples of 16, as H.264 wants)."""
MAX_EPISODES = 4
"""Episodes of env 0 recorded (one per round of ``env.num_envs`` episodes): a video of a few seconds each."""
CAMERA_EYE, CAMERA_TARGET = (0.6, 0.7, 0.6), (0.0, 0.0, 0.35)
"""ManiSkill's human-render camera (``_default_human_render_camera_configs``: ``look_at(eye, target)``) of
PushCube-v1, PickCube-v1, PullCube-v1, StackCube-v1 and LiftPegUpright-v1."""
CAMERAS = {"PegInsertionSide-v1": ((0.5, -0.5, 0.8), (0.05, -0.1, 0.4))}
"""The tasks whose human-render camera is another one: task -> (eye, target)."""


def camera(task: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The eye and target of ``task``'s ManiSkill human-render camera."""
    return CAMERAS.get(task, (CAMERA_EYE, CAMERA_TARGET))


def _why(e: BaseException) -> str:
    try:
        text = str(e)
    except Exception:  # noqa: BLE001  (PyOpenGL's EGL errors fail to format themselves)
        text = ""
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _headless_default() -> None:
    """Without a display and without ``MUJOCO_GL``: EGL. MuJoCo reads ``MUJOCO_GL`` when its renderer is first
    imported; where that happened already (GLFW chosen, which needs a display), its context class is switched."""
    if os.environ.get("MUJOCO_GL") or os.environ.get("DISPLAY"):
        return
    os.environ["MUJOCO_GL"] = "egl"
    gl = sys.modules.get("mujoco.rendering.classic.gl_context")
    if gl is not None and getattr(gl, "_MUJOCO_GL", None) in ("", "glfw", "enable", "enabled", "on", "true", "1"):
        try:
            from mujoco.egl import GLContext
        except Exception:  # noqa: BLE001  (no EGL library: the probe reports it)
            return
        gl.GLContext = GLContext


def _probe() -> None:
    """A small offscreen render: raises where MuJoCo's OpenGL context cannot be made."""
    import mujoco

    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>")
    renderer = mujoco.Renderer(model, 16, 16)
    try:
        renderer.update_scene(mujoco.MjData(model))
        renderer.render()
    finally:
        _close(renderer)


def unavailable() -> str | None:
    """Why no video can be written here, in one line (no renderer, no display, no writer), or None: imports imageio
    and MuJoCo and makes a small offscreen render."""
    try:
        import imageio  # noqa: F401
    except ImportError:
        return "no video writer: imageio is not installed (pip install imageio imageio-ffmpeg)"
    _headless_default()
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return "no renderer: MuJoCo is not installed"
    gl = os.environ.get("MUJOCO_GL", "glfw")
    try:
        _probe()
    except Exception as e:  # noqa: BLE001  (each OpenGL platform fails its own way)
        where = "no display (DISPLAY is unset)" if gl == "glfw" and not os.environ.get("DISPLAY") else "no renderer"
        return (f"{where}: MuJoCo's offscreen OpenGL context (MUJOCO_GL={gl}) cannot be made here ({_why(e)}); "
                "MUJOCO_GL=egl or osmesa needs a working EGL / OSMesa driver")  # fmt: skip
    return None


def _close(renderer) -> None:
    try:
        renderer.close()
    except Exception:  # noqa: BLE001, S110  (an EGL context already torn down at exit: nothing left to free)
        pass


class Recorder:
    """``env`` (a :func:`wpctrl.tasks.make` env) with every control step of env 0 written to ``path`` as a frame,
    for the first ``max_episodes`` of its episodes (one per round of ``env.num_envs``). Passes every other attribute
    through; :meth:`close` finishes the file. Check :func:`unavailable` first."""

    def __init__(self, env, path, max_episodes: int = MAX_EPISODES):
        import imageio.v2 as imageio
        import mujoco

        _headless_default()
        self._env, self._mujoco = env, mujoco
        solver = env.solver
        self._solver, self._model = solver, solver.mj_model
        self._data = mujoco.MjData(self._model)
        self._model.vis.headlight.ambient[:] = 0.35
        self._model.vis.headlight.diffuse[:] = 0.6
        self._renderer = mujoco.Renderer(self._model, HEIGHT, WIDTH)
        cam = self._camera = mujoco.MjvCamera()
        eye, target = camera(env.task_spec.env_id)
        d = [t - e for e, t in zip(eye, target)]
        cam.distance = math.sqrt(sum(x * x for x in d))
        cam.lookat[:] = target
        cam.azimuth = math.degrees(math.atan2(d[1], d[0]))
        cam.elevation = math.degrees(math.asin(d[2] / cam.distance))
        self._writer = imageio.get_writer(str(path), fps=FPS)
        self.path, self.frames, self.episodes, self.max_episodes = path, 0, 0, max_episodes
        self._goal = None

    def __getattr__(self, name):
        return getattr(self._env, name)

    def reset(self, *args, **kwargs):
        out = self._env.reset(*args, **kwargs)
        self.episodes += 1
        goal = self._env.task_spec.goal_name  # None: a task without a goal marker (nothing drawn)
        self._goal = self._env.get_state_dict()["actors"][goal][0, :3].tolist() if goal else None
        return out

    def step(self, action):
        out = self._env.step(action)
        if self.episodes <= self.max_episodes:
            self._frame()
        return out

    def _frame(self) -> None:
        import numpy as np

        mj = self._mujoco
        self._data.qpos[:] = self._solver.mjw_data.qpos.numpy()[0]
        mj.mj_forward(self._model, self._data)
        self._renderer.update_scene(self._data, camera=self._camera)
        scene = self._renderer.scene
        if self._goal is not None and scene.ngeom < scene.maxgeom:
            mj.mjv_initGeom(scene.geoms[scene.ngeom], mj.mjtGeom.mjGEOM_SPHERE, np.array([0.02, 0.0, 0.0]),
                            np.array(self._goal, float), np.eye(3).ravel(), np.array([0.1, 0.9, 0.1, 0.8]))  # fmt: skip
            scene.ngeom += 1
        self._writer.append_data(self._renderer.render())
        self.frames += 1

    def close(self) -> None:
        self._writer.close()
        _close(self._renderer)
        n = min(self.episodes, self.max_episodes)
        print(f"wrote {self.path} ({self.frames} frames: env 0's first {n} episode{'s' * (n != 1)})", flush=True)


def open_recorder(env, path):
    """A :class:`Recorder` of ``env`` (a Newton task env) into ``path``, or None with a one-line note on stderr saying
    why the video is skipped (no renderer, no display, no writer)."""
    why = unavailable()
    if why is None:
        try:
            return Recorder(env, path)
        except Exception as e:  # noqa: BLE001  (the writer refuses the file: an unknown extension, no ffmpeg)
            why = f"cannot write {str(path)!r} ({_why(e)})"
    print(f"wpctrl evaluate: --video skipped: {why}", file=sys.stderr, flush=True)
    return None
