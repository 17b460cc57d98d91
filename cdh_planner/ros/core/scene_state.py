"""The node's scene without the graph: the scene of ``scene_file`` changed by the obstacles
received on ``~/obstacles``, and its version. It owns its lock and imports no rclpy: the
node (``node/scene.py``) maps the topic and the service onto it, the tests drive it directly.

    state = SceneState()
    state.configure(config)                  # at configure, and after each parameter change
    update = state.update(array_msg, base_frame)   # an ObstacleArray: Update(taken, refused)
    now = state.current()                    # SceneVersion(version, scene): a goal's scene

Versions: 0 is the scene of ``scene_file`` (without one: None, nothing is checked, unless
the robot declares its platform's shape: ``scene.schema.default_scene``); each
update that takes at least one obstacle adds one, and so does each parameter change that
gives another scene (a new ``scene_file`` replaces the obstacles by the file's; a change of
``robot.*`` keeps them, with the robot's new defaults). Once an obstacle has been received
the scene is checked even when it has none left (cables against each other, the platform).
A plan is made under the scene of its arrival; a planner is made for each scene it is used
under (``PlanService``), since a planner's atlas and checks belong to one scene.
"""

import dataclasses
import threading
from dataclasses import dataclass

from cdh_planner_interfaces.msg import Obstacle

from ...errors import InputError
from ...scene.schema import MAX_OBSTACLES, Scene, check_obstacle_id, scene_from_dict
from ..msgs.scene_msgs import shape_of_obstacle

MAX_ITEMS = MAX_OBSTACLES   # obstacles in one ObstacleArray (more: refused whole)


@dataclass(frozen=True)
class SceneVersion:
    """A scene as it was at one time: ``scene`` (scene.schema.Scene, or None: no collision
    checks) and its ``version``."""

    version: int
    scene: Scene = None


@dataclass(frozen=True)
class Update:
    """What one ObstacleArray did: the ids ``taken`` (each "add ball" / "remove post"),
    the items ``refused`` (each "obstacles[2] (post): <reason>"), the resulting version."""

    version: int
    taken: tuple = ()
    refused: tuple = ()

    def line(self):
        """One line for the node's log."""
        text = f"scene version {self.version}: " + (", ".join(self.taken) or "nothing taken")
        return text + (f"; refused: {'; '.join(self.refused)}" if self.refused else "")


class SceneState:

    def __init__(self):
        self._lock = threading.Lock()
        self._now = SceneVersion(0, None)
        self._key = None         # the parameters the scene was made from (``_key``)
        self._file = None        # the scene_file value the obstacles came from
        self._preview = None     # (key, version, scene) of the last ``effective``

    def current(self):
        with self._lock:
            return self._now

    # ------------------------------------------------------------------ parameters

    def effective(self, config):
        """The scene ``config`` gives (nothing changed yet): the current one if neither
        ``scene_file`` nor ``robot.*`` changed; ``configure(config)`` then makes it current."""
        with self._lock:
            key = _key(config)
            if key == self._key:
                return self._now.scene
            scene = self._made(config)
            self._preview = (key, self._now.version, scene)
            return scene

    def configure(self, config):
        """Make the scene of ``config`` current (a new version if it is another scene)."""
        with self._lock:
            key = _key(config)
            if key == self._key:
                return self._now
            k, version, scene = self._preview or (None, None, None)
            if (k, version) != (key, self._now.version):
                scene = self._made(config)
            first = self._key is None
            self._key, self._file, self._preview = key, config.values.get("scene_file"), None
            self._now = SceneVersion(0 if first else self._now.version + 1, scene)
            return self._now

    def _made(self, config):
        """The scene of ``config``: its scene_file's, with the obstacles received kept unless
        scene_file is another file."""
        now = self._now.scene
        if now is None or config.values.get("scene_file") != self._file:
            return config.scene
        base = config.scene if config.scene is not None else scene_from_dict({}, config.robot)
        return dataclasses.replace(base, obstacles=now.obstacles)

    # ------------------------------------------------------------------ ~/obstacles

    def update(self, msg, base_frame, robot=None):
        """Apply an ObstacleArray: each item is taken or refused on its own (ADD puts or
        replaces an obstacle, REMOVE takes one away); a wrong frame or too many items
        refuse it whole. ``robot``: the defaults of a scene made from nothing."""
        frame = msg.header.frame_id
        if frame != base_frame:
            return Update(self.current().version, refused=(
                f"header.frame_id '{frame}': must be the base frame '{base_frame}'",))
        if len(msg.obstacles) > MAX_ITEMS:
            return Update(self.current().version, refused=(
                f"obstacles: {len(msg.obstacles)} items, at most {MAX_ITEMS}",))
        with self._lock:
            scene = self._now.scene
            if scene is None:
                scene = scene_from_dict({}, robot)
            obstacles = {o.id: o for o in scene.obstacles}
            taken, refused = [], []
            for i, item in enumerate(msg.obstacles):
                try:
                    taken.append(_apply(obstacles, item, f"obstacles[{i}]"))
                except InputError as exc:
                    refused.append(f"obstacles[{i}] ({item.id or 'no id'}): {exc}")
            if taken:
                scene = dataclasses.replace(scene, obstacles=tuple(obstacles.values()))
                self._now = SceneVersion(self._now.version + 1, scene)
            return Update(self._now.version, tuple(taken), tuple(refused))


def _apply(obstacles, item, where):
    """One Obstacle message applied to ``obstacles`` (id -> Shape, in order); what it did."""
    if item.operation == Obstacle.REMOVE:
        oid = check_obstacle_id(item.id, f"{where}.id")
        if obstacles.pop(oid, None) is None:
            raise InputError(f"{where}.id", oid, "no obstacle of this id to remove")
        return f"remove {oid}"
    if item.operation != Obstacle.ADD:
        raise InputError(f"{where}.operation", int(item.operation), "expected ADD (0) or "
                                                                   "REMOVE (1)")
    shape = shape_of_obstacle(item, where)
    if shape.id not in obstacles and len(obstacles) >= MAX_OBSTACLES:
        raise InputError(where, shape.id, f"the scene has {MAX_OBSTACLES} obstacles already")
    verb = "replace" if shape.id in obstacles else "add"
    obstacles[shape.id] = shape
    return f"{verb} {shape.id}"


def _key(config):
    """What the scene depends on among the parameters: scene_file and robot.*."""
    values = config.values
    return (values.get("scene_file"),) + tuple(
        (k, repr(v)) for k, v in sorted(values.items()) if k.startswith("robot."))
