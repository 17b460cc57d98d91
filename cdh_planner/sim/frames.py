"""A strip of rendered frames of a run (``cdh-planner simulate --frames``): the platform at
FRAMES evenly spaced times, seen by the model's ``workspace`` camera, side by side in one PNG.

Offscreen rendering needs an OpenGL library: headless, MuJoCo's EGL backend (MUJOCO_GL=egl,
which ``simulate`` sets unless MUJOCO_GL is given) with the system's libegl1, libegl-mesa0
and libgl1-mesa-dri (Mesa's software renderer). Without one, ``render_strip`` raises
NoRendering with one line saying so; everything else of the run stands.
"""

import numpy as np

FRAMES = 6
WIDTH, HEIGHT = 480, 360   # px per frame


class NoRendering(RuntimeError):
    """No OpenGL context could be made for offscreen rendering."""


def render_strip(plant, record, out, frames=FRAMES):
    """Render the recorded poses of ``record`` (run.Record) at ``frames`` evenly spaced
    times with ``plant``'s model (plant.SimulatedRobot) and write them side by side to
    ``out`` (PNG). Returns the times (s) shown."""
    from .plant import GL_FAILURE
    picks = np.linspace(0, len(record.t) - 1, frames).round().astype(int)
    if GL_FAILURE:
        raise NoRendering(f"no OpenGL for offscreen rendering ({GL_FAILURE[0]}); headless: "
                          f"apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri, MUJOCO_GL=egl")
    try:
        images = _render(plant, record, picks)
    except Exception as exc:   # noqa: BLE001 - ImportError (no backend), mujoco.FatalError,
        # RuntimeError, AttributeError from PyOpenGL without its library: all "no OpenGL"
        text = str(exc).splitlines()[0] if str(exc) else ""
        raise NoRendering(f"no OpenGL for offscreen rendering ({type(exc).__name__}: {text}); "
                          f"headless: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri, "
                          f"MUJOCO_GL=egl") from None
    import matplotlib.image
    matplotlib.image.imsave(out, np.concatenate(images, axis=1))
    return record.t[picks]


def _render(plant, record, picks):
    """The frames (list of (HEIGHT, WIDTH, 3) uint8) of the recorded poses at ``picks``."""
    from .plant import _mujoco
    mujoco = _mujoco()
    renderer = mujoco.Renderer(plant.model, HEIGHT, WIDTH)
    try:
        images = []
        for k in picks:
            q = record.quaternion[k]
            plant.data.qpos[:7] = np.concatenate([record.p[k], [q[3], q[0], q[1], q[2]]])
            plant.data.qvel[:] = 0.0
            mujoco.mj_forward(plant.model, plant.data)
            renderer.update_scene(plant.data, camera="workspace")
            images.append(renderer.render().copy())
        return images
    finally:
        renderer.close()
