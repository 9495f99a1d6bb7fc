# SPDX-License-Identifier: MIT
"""b21r_foxglove: the product's LCM messages as Foxglove messages, one conversion shared by the
MCAP converter (tools/b21r_mcap.py) and the live bridge (tools/b21r_foxglove_bridge.py).

Schemas (docs/tools.md says why): the well-known data in Foxglove's own schemas, protobuf-encoded
by foxglove-sdk (the schema travels in the file or the WebSocket advertisement, so Foxglove needs
no plugin and nothing is copied by hand); the product's own messages as JSON with a JSON Schema
generated from the LCM definitions (lib/msgs), field for field.

| topic | schema | from |
|---|---|---|
| /laser | foxglove.LaserScan, frame laser (no return: NaN) | B21R_SCAN |
| /tf | foxglove.FrameTransforms: world -> odom (per run), odom -> base_link, base_link -> laser | B21R_POSE, B21R_EXPERIENCE, B21R_RUN |
| /odom/pose | foxglove.PoseInFrame, frame odom (the base's odometry) | B21R_POSE |
| /world/pose | foxglove.PoseInFrame, frame world (the task frame: corridor, arena or room) | B21R_POSE + the run's start |
| /world/trajectory | foxglove.PosesInFrame, frame world: the run so far (every TRAJECTORY_EVERY poses and at its end) | same |
| /scene | foxglove.SceneUpdate, frame world: walls, obstacles, goal | B21R_CONFIG (task) and the world |
| /command | JSON, geometry_msgs/Twist-shaped: linear.x [m/s], angular.z [rad/s] commanded | B21R_EXPERIENCE |
| /b21r/experience, /run, /eval, /status, /config, /teleop, /command | JSON of the LCM fields (arrays cut to their valid count) | same channel |

Every message's timestamp is its receive time (the LCM log event's time, or the bridge's clock),
so that poses, transforms, scans and the scene share one clock; the controller's own time stays in
the product messages' utime. The task-frame pose of a run: from its B21R_RUN start pose when the
caller knows it beforehand (the converter reads the log twice), else from the run's first state
(corridor: exact inverse of the features; doorway: the features' door frame placed at the world's
door; obstacles: the goal and the nearest obstacle as two landmarks of the world), composed with
the odometry since the run's first pose. The scene's world: the corridor of the configuration's
length, or any other task's world as its declaration builds it (b21r_task_world), or --world FILE;
where it cannot be built the scene stays empty and the reason is printed.
"""
import math
import sys

from foxglove import messages as fm

import b21r
from b21r_log import FIRST_DECISION_STEPS
from b21r_task_world import declared_world, parse_task_params, task_name
from b21r_trajectories import CORRIDOR, corridor_pose, read_world

# The laser's mount on the B21r (sim/include/sim/plant.h: SIM_LASER_X_DEFAULT_M, and its height).
LASER_X_M = 0.15
LASER_Z_M = 0.355
ROBOT_RADIUS_M = 0.26  # protocols.md C: the base skirt
TRAJECTORY_EVERY = 10  # poses between two /world/trajectory messages (1 s at 10 Hz)
TRAJECTORY_MAX = 2000  # poses kept of a run (the step limit is 1000)

TASK_CORRIDOR = b21r.experience_t.TASK_CORRIDOR
TASK_OBSTACLES = b21r.experience_t.TASK_OBSTACLES
TASK_DOORWAY = b21r.experience_t.TASK_DOORWAY

# LCM channel -> the JSON topic of the product message.
PRODUCT_TOPICS = {
    "B21R_EXPERIENCE": "/b21r/experience",
    "B21R_RUN": "/b21r/run",
    "B21R_EVAL": "/b21r/eval",
    "B21R_STATUS": "/b21r/status",
    "B21R_CONFIG": "/b21r/config",
    "B21R_TELEOP": "/b21r/teleop",
    "B21R_COMMAND": "/b21r/command",
}
# Arrays cut to their valid count: field -> the field that counts it.
VALID_COUNT = {"s": "state_dim", "s_next": "state_dim", "steps": "n_starts", "success": "n_starts"}

_JSON_TYPES = {"int8_t": "integer", "int16_t": "integer", "int32_t": "integer", "int64_t": "integer",
               "byte": "integer", "float": "number", "double": "number", "boolean": "boolean", "string": "string"}

TWIST_SCHEMA = {
    "title": "geometry_msgs/Twist (commanded)",
    "type": "object",
    "properties": {
        "linear": {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"},
                   "description": "translation velocity [m/s] (x forward)"},
        "angular": {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"},
                    "description": "rotation velocity [rad/s] (z, CCW positive)"},
        "run_id": {"type": "integer"},
        "step_id": {"type": "integer"},
    },
}


def lcm_json_schema(lcm_type):
    """A JSON Schema of an LCM type (generated Python class of lib/msgs), field for field."""
    props = {}
    for name, tname, dims in zip(lcm_type.__slots__, lcm_type.__typenames__, lcm_type.__dimensions__):
        item = {"type": _JSON_TYPES.get(tname, "object")}
        if dims:
            for d in reversed(dims):
                item = {"type": "array", "items": item}
                if isinstance(d, int) and name not in VALID_COUNT:
                    item["maxItems"] = d
        props[name] = item
    return {"title": "b21r.%s" % lcm_type.__name__, "type": "object", "properties": props}


def _json_value(x):
    # JSON has no NaN or infinity: such a number becomes null.
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, bytes):
        return x.decode("utf-8", "replace")
    return x


def lcm_to_dict(msg):
    """The fields of a decoded LCM message as JSON-ready Python values (non-finite numbers: null)."""
    out = {}
    for name in msg.__slots__:
        v = getattr(msg, name)
        if isinstance(v, (list, tuple)):
            v = list(v)
            if name in VALID_COUNT:
                v = v[:max(0, getattr(msg, VALID_COUNT[name]))]
            v = [_json_value(x) for x in v]
        else:
            v = _json_value(v)
        out[name] = v
    return out


def product_schemas():
    """topic -> JSON Schema of every product topic."""
    types = {ch: _type_of_channel(ch) for ch in PRODUCT_TOPICS}
    schemas = {topic: lcm_json_schema(types[ch]) for ch, topic in PRODUCT_TOPICS.items()}
    schemas["/command"] = TWIST_SCHEMA
    return schemas


def _type_of_channel(channel):
    return {"B21R_EXPERIENCE": b21r.experience_t, "B21R_RUN": b21r.run_t, "B21R_EVAL": b21r.eval_t,
            "B21R_STATUS": b21r.status_t, "B21R_CONFIG": b21r.config_t, "B21R_TELEOP": b21r.teleop_t,
            "B21R_COMMAND": b21r.command_t}[channel]


# topic -> Foxglove message class of the well-known topics.
FOXGLOVE_TOPICS = {
    "/laser": fm.LaserScan,
    "/tf": fm.FrameTransforms,
    "/odom/pose": fm.PoseInFrame,
    "/world/pose": fm.PoseInFrame,
    "/world/trajectory": fm.PosesInFrame,
    "/scene": fm.SceneUpdate,
}


def all_topics():
    """Every topic the conversion can produce: topic -> ("protobuf", Foxglove class) or ("json", JSON Schema)."""
    out = {t: ("protobuf", cls) for t, cls in FOXGLOVE_TOPICS.items()}
    out.update({t: ("json", s) for t, s in product_schemas().items()})
    return out


# ---- geometry -------------------------------------------------------------------------------

def compose(a, b):
    """Pose a ∘ b of planar poses (x, y, theta)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def inverse(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


def _stamp(t_ns):
    return fm.Timestamp(int(t_ns // 1_000_000_000), int(t_ns % 1_000_000_000))


def _pose(x, y, theta, z=0.0):
    return fm.Pose(position=fm.Vector3(x=x, y=y, z=z),
                   orientation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2)))


def _transform(t_ns, parent, child, p, z=0.0):
    return fm.FrameTransform(timestamp=_stamp(t_ns), parent_frame_id=parent, child_frame_id=child,
                             translation=fm.Vector3(x=p[0], y=p[1], z=z),
                             rotation=fm.Quaternion(x=0.0, y=0.0, z=math.sin(p[2] / 2), w=math.cos(p[2] / 2)))


# ---- the world ------------------------------------------------------------------------------

def world_for(task, config_settings, world_file=None, repo=None):
    """The world drawn in the scene: world_file when given; else the corridor of the configuration's
    length for the corridor task; else any other task's world as its declaration builds it, with
    the configuration's task_params (b21r_task_world). A task whose world cannot be built here
    (no compiled b21r_learn, a task byte this build does not declare) draws no world, with the
    reason in the result's "unavailable"."""
    if world_file is not None:
        return read_world(world_file)
    if task == TASK_CORRIDOR:
        length = CORRIDOR["length_m"]
        try:
            length = float(config_settings.get("corridor_length_m", length))
        except (TypeError, ValueError):
            pass
        return {"walls": [], "cylinders": [], "goal": None, "starts": [], "corridor": (length, CORRIDOR["width_m"])}
    from b21r_task_world import WorldUnavailable
    name = task_name(task)
    try:
        if name is None:
            raise WorldUnavailable("task byte %s is not a declared task" % task)
        return declared_world(name, parse_task_params(config_settings.get("task_params")))
    except WorldUnavailable as exc:
        return {"walls": [], "cylinders": [], "goal": None, "starts": [], "corridor": None, "unavailable": str(exc)}


def scene_entities(world, t_ns):
    """The world as scene entities (frame world): walls as boxes, cylinders, the goal."""
    wall_colour = fm.Color(r=0.35, g=0.35, b=0.35, a=1.0)
    thick, height = 0.05, 0.5
    boxes = []

    def wall(x0, y0, x1, y1, t=None):
        # A face (x0, y0) -> (x1, y1) with its solid of thickness t to the right (sim/world.h); a bare
        # segment (no thickness) is drawn thin, centred on it.
        length = math.hypot(x1 - x0, y1 - y0)
        if length == 0.0:
            return
        cx, cy, w = (x0 + x1) / 2, (y0 + y1) / 2, thick
        if t is not None and t > 0.0:
            cx, cy, w = cx + (y1 - y0) / length * t / 2, cy - (x1 - x0) / length * t / 2, t
        boxes.append(fm.CubePrimitive(pose=_pose(cx, cy, math.atan2(y1 - y0, x1 - x0), height / 2),
                                      size=fm.Vector3(x=length, y=w, z=height), color=wall_colour))

    goal = []
    if world.get("corridor") is not None:
        length, width = world["corridor"]
        h = width / 2
        for seg in ((0, h, length, h), (0, -h, length, -h), (0, -h, 0, h), (length, -h, length, h)):
            wall(*seg)
        gx = length - CORRIDOR["goal_distance_m"]
        # The goal: the last goal_distance_m of the corridor.
        goal.append(fm.CubePrimitive(pose=_pose((gx + length) / 2, 0.0, 0.0, 0.005),
                                     size=fm.Vector3(x=length - gx, y=width, z=0.01),
                                     color=fm.Color(r=0.3, g=0.75, b=0.3, a=0.4)))
    for seg in world.get("walls", []):
        wall(*seg)
    cylinders = [fm.CylinderPrimitive(pose=_pose(x, y, 0.0, height / 2), size=fm.Vector3(x=2 * r, y=2 * r, z=height),
                                      bottom_scale=1.0, top_scale=1.0, color=fm.Color(r=0.54, g=0.43, b=0.23, a=1.0))
                 for x, y, r in world.get("cylinders", [])]
    goal_cyl = []
    if world.get("goal") is not None:
        x, y, r = world["goal"]
        goal_cyl.append(fm.CylinderPrimitive(pose=_pose(x, y, 0.0, 0.005), size=fm.Vector3(x=2 * r, y=2 * r, z=0.01),
                                             bottom_scale=1.0, top_scale=1.0, color=fm.Color(r=0.3, g=0.75, b=0.3, a=0.5)))
    stamp = _stamp(t_ns)
    return fm.SceneUpdate(entities=[
        fm.SceneEntity(timestamp=stamp, frame_id="world", id="walls", cubes=boxes),
        fm.SceneEntity(timestamp=stamp, frame_id="world", id="obstacles", cylinders=cylinders),
        fm.SceneEntity(timestamp=stamp, frame_id="world", id="goal", cubes=goal, cylinders=goal_cyl),
    ])


def start_from_state(task, s, world):
    """The task-frame pose (x, y, theta) at a learner state s of the task, or None where the
    state does not determine it. Corridor: the inverse of the features (end distance, lateral
    fraction, target angle). Doorway: the door frame of the features (wall distance, offset,
    heading; features/doorway.h) placed at the world's door (the gap between its two walls across
    the room). Obstacles: the goal (the world's) and the nearest obstacle (the world's cylinder that
    fits the two ranges best) as landmarks; None without a visible obstacle."""
    if task == TASK_CORRIDOR:
        x, y, th = corridor_pose(s)
        if world.get("corridor") is not None:
            x += world["corridor"][0] - CORRIDOR["length_m"]  # corridor_pose assumes the default length
        return (x, y, th)
    if task == TASK_DOORWAY:
        door = door_of(world)
        if door is None or len(s) < 3:
            return None
        wall_x, door_y = door
        return (wall_x - s[0], door_y + s[1], s[2])
    if task != TASK_OBSTACLES or world.get("goal") is None or not world.get("cylinders") or len(s) < 4:
        return None
    gb, gd, ob, od = s[0], s[1], s[2], s[3]
    if not (math.isfinite(od) and od > 0.0 and gd > 0.0):
        return None
    gx, gy, _ = world["goal"]
    g_r = (gd * math.cos(gb), gd * math.sin(gb))
    best = None
    for cx, cy, r in world["cylinders"]:
        c_r = ((od + r) * math.cos(ob), (od + r) * math.sin(ob))
        seen = math.hypot(c_r[0] - g_r[0], c_r[1] - g_r[1])
        mismatch = abs(seen - math.hypot(cx - gx, cy - gy))
        th = math.atan2(cy - gy, cx - gx) - math.atan2(c_r[1] - g_r[1], c_r[0] - g_r[0])
        c, sn = math.cos(th), math.sin(th)
        pose = (gx - (c * g_r[0] - sn * g_r[1]), gy - (sn * g_r[0] + c * g_r[1]), math.atan2(sn, c))
        if best is None or mismatch < best[0]:
            best = (mismatch, pose)
    return best[1]


def door_of(world):
    """(x of the wall's centre plane, y of the door's centre) of a world with a dividing wall along
    y made of walls on one line with a gap between them (the doorway task's), or None."""
    lines = {}
    for w in world.get("walls", []):
        if len(w) >= 5 and abs(w[0] - w[2]) < 1e-9 and w[1] != w[3]:
            # The centre plane: the solid lies to the face's right.
            centre = w[0] + (w[4] / 2 if w[3] > w[1] else -w[4] / 2)
            lines.setdefault(round(centre, 6), []).append((min(w[1], w[3]), max(w[1], w[3])))
    for x, spans in sorted(lines.items()):
        spans.sort()
        for (_, hi), (lo, _) in zip(spans, spans[1:]):
            if lo > hi:
                return (x, (hi + lo) / 2)
    return None


class Converter:
    """Turns decoded B21R_* messages, in receive order, into (topic, message) pairs: a Foxglove
    message object for the well-known topics, a dict for the JSON ones.

    known_starts: {run_id: (x, y, theta)} task-frame start poses known beforehand (the B21R_RUN
    records of a log); runs without one take theirs from their first state. world_file: the
    world to draw (default: the task's). repo: the checkout (for the default worlds)."""

    def __init__(self, repo, world_file=None, known_starts=None, default_task=TASK_CORRIDOR):
        self.repo = repo
        self.world_file = world_file
        self.known_starts = dict(known_starts or {})
        self.task = None
        self.default_task = default_task
        self.world = None
        self.settings = {}
        self.run_id = None
        self.odom_start = None   # odometry pose at the run's first pose
        self.world_odom = None   # world -> odom transform of the run, once known
        self.pending_poses = []  # the run's odometry poses before world_odom is known
        self.trajectory = []
        self.poses_since = 0
        self.first_states = {}   # run_id -> (task, first state) of runs whose first pose may come later
        self.first_exp_run = None  # the run whose first experience was seen last
        self.warned = set()      # reasons already given for a world not drawn

    # -- world --
    def _scene(self, t_ns, task):
        self.task = task
        self.world = world_for(task, self.settings, self.world_file, self.repo)
        why = self.world.get("unavailable")
        if why and why not in self.warned:
            self.warned.add(why)
            print("b21r_foxglove: no world drawn for task %s: %s" % (task, why), file=sys.stderr)
        return [("/scene", scene_entities(self.world, t_ns))]

    def _ensure_world(self, t_ns, task=None):
        if self.world is None:
            return self._scene(t_ns, self.default_task if task is None else task)
        if task is not None and task != self.task and self.world_file is None:
            return self._scene(t_ns, task)
        return []

    # -- per message --
    def convert(self, channel, msg, t_ns):
        """The (topic, message) pairs for one received message at receive time t_ns [ns]."""
        out = []
        if channel in PRODUCT_TOPICS:
            if channel == "B21R_CONFIG":
                self.settings = {}
                for line in msg.text.splitlines():
                    key, sep, value = line.partition(" = ")
                    if sep:
                        self.settings[key.strip()] = value.strip().strip('"')
                self.world = None
                out += self._ensure_world(t_ns, msg.task)
            out.append((PRODUCT_TOPICS[channel], lcm_to_dict(msg)))
        if isinstance(msg, b21r.scan_t):
            n = max(0, msg.n_beams)
            ranges = [float(r) if r > 0.0 else float("nan") for r in msg.ranges_m[:n]]
            out.append(("/laser", fm.LaserScan(timestamp=_stamp(t_ns), frame_id="laser", pose=_pose(0.0, 0.0, 0.0),
                                               start_angle=float(msg.angle_min_rad),
                                               end_angle=float(msg.angle_min_rad + msg.angle_increment_rad * max(0, n - 1)),
                                               ranges=ranges)))
        elif isinstance(msg, b21r.pose_t):
            out += self._pose(msg, t_ns)
        elif isinstance(msg, b21r.experience_t):
            out += self._ensure_world(t_ns, msg.task)
            out.append(("/command", {"linear": {"x": msg.translation_mps, "y": 0.0, "z": 0.0},
                                     "angular": {"x": 0.0, "y": 0.0, "z": msg.action_radps},
                                     "run_id": msg.run_id, "step_id": msg.step_id}))
            # A run's first experience starts from its first state: with decisions over N ticks it
            # ends at step N - 1, its s still the state at step 0.
            first = msg.run_id != self.first_exp_run and msg.step_id < FIRST_DECISION_STEPS
            if first:
                self.first_exp_run = msg.run_id
                state = (msg.task, list(msg.s[:msg.state_dim]))
                if msg.run_id == self.run_id:
                    if self.world_odom is None:
                        out += self._anchor_from_state(*state, t_ns)
                else:
                    self.first_states = {msg.run_id: state}  # its poses come next
        elif isinstance(msg, b21r.run_t):
            if msg.run_id == self.run_id and self.trajectory:
                out.append(self._trajectory(t_ns))
        return out

    def _pose(self, msg, t_ns):
        out = []
        if msg.run_id < 0:
            return out
        p = (msg.x_m, msg.y_m, msg.theta_rad)
        tfs = [_transform(t_ns, "odom", "base_link", p), _transform(t_ns, "base_link", "laser", (LASER_X_M, 0.0, 0.0),
                                                                   LASER_Z_M)]
        out.append(("/odom/pose", fm.PoseInFrame(timestamp=_stamp(t_ns), frame_id="odom", pose=_pose(*p))))
        if msg.run_id != self.run_id:
            self.run_id = msg.run_id
            self.odom_start = p
            self.world_odom = None
            self.pending_poses = []
            self.trajectory = []
            self.poses_since = 0
            out += self._ensure_world(t_ns)
            if msg.run_id in self.known_starts:
                out += self._anchor(self.known_starts[msg.run_id], t_ns)
            elif msg.run_id in self.first_states:
                out += self._anchor_from_state(*self.first_states.pop(msg.run_id), t_ns)
        if self.world_odom is None:
            self.pending_poses.append(p)
        else:
            tfs.append(_transform(t_ns, "world", "odom", self.world_odom))
            out += self._world_pose(p, t_ns)
        out.insert(0, ("/tf", fm.FrameTransforms(transforms=tfs)))
        return out

    def _anchor_from_state(self, task, s, t_ns):
        start = start_from_state(task, s, self.world)
        return self._anchor(start, t_ns) if start is not None else []

    def _anchor(self, start, t_ns):
        """The run's task-frame start is known: world -> odom, and the poses seen so far."""
        self.world_odom = compose(start, inverse(self.odom_start))
        out = [("/tf", fm.FrameTransforms(transforms=[_transform(t_ns, "world", "odom", self.world_odom)]))]
        for p in self.pending_poses:
            self.trajectory.append(compose(self.world_odom, p))
        self.pending_poses = []
        return out

    def _world_pose(self, p, t_ns):
        w = compose(self.world_odom, p)
        out = [("/world/pose", fm.PoseInFrame(timestamp=_stamp(t_ns), frame_id="world", pose=_pose(*w)))]
        if len(self.trajectory) < TRAJECTORY_MAX:
            self.trajectory.append(w)
        self.poses_since += 1
        if self.poses_since >= TRAJECTORY_EVERY:
            out.append(self._trajectory(t_ns))
        return out

    def _trajectory(self, t_ns):
        self.poses_since = 0
        return ("/world/trajectory", fm.PosesInFrame(timestamp=_stamp(t_ns), frame_id="world",
                                                     poses=[_pose(*q) for q in self.trajectory]))


def encode(topic_kind, message):
    """The bytes of a converted message: protobuf for Foxglove classes, JSON for dicts."""
    if topic_kind == "json":
        import json
        return json.dumps(message, allow_nan=False, separators=(",", ":")).encode()
    return message.encode()
