# SPDX-License-Identifier: MIT
"""b21r_task_world: the world of any declared task (lib/tasks) as the drawing tools use it, from the
task's own declaration (b21r_learn's compiled core builds it exactly as the emulator does), so that
a tool draws a new task's room without code of its own.

A world is a dict: "walls" [(x0, y0, x1, y1, thickness)] (each wall's face with its solid to the
right, as sim/world.h), "cylinders" [(x, y, r)], "goal" (x, y, r) or None, "starts" [(x, y, theta)]
(the evaluation poses), "corridor" (length, width) or None (the corridor task's own drawing, which
marks its goal line), "task" (the task's name) and "bounds" (x0, y0, x1, y1).
"""

class WorldUnavailable(Exception):
    """The declared world cannot be built here (no compiled b21r_learn, an unknown task)."""


def _core():
    try:
        from b21r_learn import _core as core  # noqa: WPS433 (the compiled part, found by b21r_bootstrap)
    except ImportError as exc:
        raise WorldUnavailable("drawing a task's world needs b21r_learn's compiled part (build the host-release "
                               "preset: cmake --build --preset host-release), or give --world FILE (%s)" % exc)
    return core


def task_names():
    """Message task byte -> task name, for every declared task: the registry's, else the names the
    message definitions give the task byte (b21r.experience_t TASK_*)."""
    try:
        return {t["id"]: t["name"] for t in _core().tasks()}
    except WorldUnavailable:
        import b21r
        return {getattr(b21r.experience_t, k): k[len("TASK_"):].lower()
                for k in dir(b21r.experience_t) if k.startswith("TASK_")}


def task_name(task_id):
    """The name of the task with message id task_id, or None when no task has it."""
    return task_names().get(task_id)


def parse_task_params(text):
    """A configuration's task_params ("name=value,name=value") as a dict of floats; bad items are
    skipped (the controller has refused them already)."""
    out = {}
    for item in (text or "").split(","):
        k, sep, v = item.partition("=")
        if sep:
            try:
                out[k.strip()] = float(v)
            except ValueError:
                pass
    return out


def declared_world(task, params=None):
    """The world of the task named `task`, with its declared parameters `params` ({name: value},
    e.g. a configuration's task_params) applied. Raises WorldUnavailable with the reason when the
    world cannot be built here."""
    core = _core()
    names = [t["name"] for t in core.tasks()]
    if task not in names:
        raise WorldUnavailable("task '%s' is not declared in this build (declared: %s)" % (task, ", ".join(names)))
    try:
        env = core.Env(task, "kinematic", dict(params or {}), {}, None, None)
    except (TypeError, ValueError) as exc:
        raise WorldUnavailable("task %s with parameters %s: %s" % (task, params, exc))
    w = env.world()
    spec = env.spec()
    return {"task": task, "walls": [tuple(x) for x in w["walls"]], "cylinders": [tuple(c) for c in w["cylinders"]],
            "goal": tuple(w["goal"]) if w["goal"] is not None else None,
            "starts": [tuple(p) for p in spec.get("eval_starts", [])], "corridor": None, "bounds": tuple(w["bounds"])}


def wall_outline(wall):
    """The four corners of a wall's solid: a 5-tuple (face with the solid to its right, thickness),
    or None for a bare face (x0, y0, x1, y1)."""
    if len(wall) < 5 or not wall[4] > 0.0:
        return None
    x0, y0, x1, y1, t = wall[:5]
    dx, dy = x1 - x0, y1 - y0
    n = (dx * dx + dy * dy) ** 0.5
    if n == 0.0:
        return None
    rx, ry = dy / n * t, -dx / n * t  # to the face's right
    return [(x0, y0), (x1, y1), (x1 + rx, y1 + ry), (x0 + rx, y0 + ry)]
