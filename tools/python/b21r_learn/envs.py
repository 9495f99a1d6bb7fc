# SPDX-License-Identifier: MIT
"""The B21r tasks as Gymnasium environments (C core: sim/env.h)."""
import math

import gymnasium
import numpy as np
from gymnasium import spaces

from . import _core

# Every task declared in lib/tasks (its registry) is an environment: task name -> Gymnasium id.
ENV_IDS = {t["name"]: t["env_id"] for t in _core.tasks()}
# tasks_end_reason_t -> name (info["reason"]).
REASONS = ("none", "goal", "collision", "step_limit")
_STARTS = {"training": _core.START_TRAINING, "eval": _core.START_EVAL, "pose": _core.START_POSE}


class B21rEnv(gymnasium.Env):
    """One of the declared tasks (lib/tasks) on the emulated B21r (``backend="ode"``) or the
    idealised kinematic model (``backend="kinematic"``).

    - Observation: the task's state vector exactly as the controller computes it (float64):
      corridor ``[end distance m, lateral fraction, target angle rad]``, obstacles
      ``[goal bearing rad, goal distance m, obstacle bearing rad, obstacle distance m, age s]``
      (the nearest obstacle seen or, after it left the laser's 180° view, remembered where it was
      last seen, carried along by odometry, for up to ``memory_s`` (3 s), and the time since it
      was seen: pi, 8 m and the memory's span when no obstacle is known), doorway
      ``[wall distance m, offset from the door's line m, heading rad, nearer jamb's distance m]``
      (``b21r_learn._core.tasks()`` names every task's).
    - Action: rotation velocity [rad/s], shape (1,), within ``[-omega_max, omega_max]``
      (default 1 rad/s). The translation speed comes from the task's speed policy. Both are
      clamped like the controller's commands (velocity, then acceleration limits); the command
      actually sent is ``info["action"]`` / ``info["translation_mps"]``.
    - Reward and termination from lib/tasks (the paper's, section V):

      ========= ============== ================ ===================================
      task      goal reached   collision        otherwise
      ========= ============== ================ ===================================
      corridor  +10, ends      0, ends          0 (step limit 1000: truncated)
      obstacles +1, ends       -1, ends         0 (step limit 500: truncated)
      doorway   +1, ends       -1, ends         0 (step limit 500: truncated)
      ========= ============== ================ ===================================

      The corridor's 0 at a wall is the paper's task ("10 for reaching the end of the corridor,
      and zero in all other situations"), not an omission: every value there is >= 0 and a
      collision is absorbing, so a wall's value 0 is already the least any state can have (the
      goal is worth 10 * gamma^steps > 0), and the learner avoids walls without a penalty. The
      obstacle task's -1 is also the paper's; there it matters, because an obstacle can be
      passed close by and the goal then still reached.
    - ``reset(seed=s)`` seeds everything (the ODE back-end's emulator gets ``s`` itself).
      ``options``: ``{"start": "training"}`` (default: the training distribution),
      ``{"start": "eval", "eval_index": i}`` (one of the 10 evaluation poses; without an index
      they are taken in turn), or ``{"pose": (x, y, theta)}`` (task frame, m and rad).
    - ``render()`` (``render_mode="rgb_array"``): the overhead view (walls, obstacles, goal,
      robot, laser rays) as an RGB array.

    Keyword arguments: ``spec`` (task settings by name, e.g. ``{"step_limit": 500}``; see
    ``env.unwrapped.task_spec``), ``limits`` (command limits, e.g.
    ``{"max_rotation_radps": 0.5}``), ``laser_noise_sigma_m``, ``laser_error_code_prob``,
    ``start`` (the default start of reset).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, task="corridor", backend="ode", render_mode=None, start="training", spec=None,
                 limits=None, laser_noise_sigma_m=None, laser_error_code_prob=None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError("render_mode must be None or 'rgb_array', not %r" % (render_mode,))
        if render_mode == "rgb_array":
            _require_pillow()
        if start not in ("training", "eval"):
            raise ValueError("start must be 'training' or 'eval', not %r" % (start,))
        self.task = task
        self.backend = backend
        self.render_mode = render_mode
        self._default_start = start
        self.core = _core.Env(task, backend, spec or {}, limits or {}, laser_noise_sigma_m,
                              laser_error_code_prob)
        low, high = self.core.state_bounds()
        self.observation_space = spaces.Box(low=low, high=high, dtype=np.float64)
        bound = self.core.action_bound
        self.action_space = spaces.Box(low=-bound, high=bound, shape=(1,), dtype=np.float32)
        self._seeded = False
        self._next_eval = 0
        self._world = None

    @property
    def task_spec(self):
        """The task's settings in use (spec fields, command limits, laser noise)."""
        return self.core.spec()

    def driver_action(self, driver):
        """The action of an example driver (b21r_learn.Driver) for the newest observation: the
        controller's phase-one teacher, computed from the same features (advances the driver)."""
        return driver.act(self.core)

    # ---- Gymnasium API ---------------------------------------------------------------------

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None:
            self.core.seed(seed)
            self._seeded = True
            self._next_eval = 0
        elif not self._seeded:
            # Unseeded: one draw from Gymnasium's generator (itself seeded from the OS).
            self.core.seed(int(self.np_random.integers(0, 2**63 - 1)))
            self._seeded = True
        options = options or {}
        start = "pose" if "pose" in options else options.get("start", self._default_start)
        if start not in _STARTS:
            raise ValueError("options['start'] must be 'training', 'eval' or 'pose', not %r" % (start,))
        index = 0
        if start == "eval":
            index = options.get("eval_index")
            if index is None:
                index = self._next_eval
                self._next_eval = (self._next_eval + 1) % _core.N_EVAL_STARTS
            index = int(index)
        obs = self.core.reset(_STARTS[start], index, options.get("pose"))
        info = {"start_pose": self.core.truth()["start_pose"]}
        if start == "eval":
            info["eval_index"] = index
        return obs, info

    def step(self, action):
        if isinstance(action, np.ndarray):
            action = action.reshape(-1)[0]
        obs, reward, terminated, truncated, reason, executed, v, steps = self.core.step(float(action))
        info = {"reason": REASONS[reason], "action": executed, "translation_mps": v, "steps": steps}
        return obs, reward, terminated, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return self._draw()

    def close(self):
        self.core = None
        super().close()

    # ---- drawing ---------------------------------------------------------------------------

    def _draw(self, width_px=800, max_height_px=600, margin_m=0.3):
        # Pillow is imported here so that environments without rendering never need it.
        _require_pillow()
        from PIL import Image, ImageDraw

        if self._world is None:
            self._world = self.core.world()
        w = self._world
        x0, y0, x1, y1 = w["bounds"]
        x0 -= margin_m
        y0 -= margin_m
        x1 += margin_m
        y1 += margin_m
        scale = min(width_px / (x1 - x0), max_height_px / (y1 - y0))
        size = (max(1, int(round((x1 - x0) * scale))), max(1, int(round((y1 - y0) * scale))))
        img = Image.new("RGB", size, (250, 250, 247))
        draw = ImageDraw.Draw(img)

        def px(x, y):  # world (y up) -> image (y down)
            return ((x - x0) * scale, (y1 - y) * scale)

        if w["goal"] is not None:
            gx, gy, gr = w["goal"]
            draw.ellipse([px(gx - gr, gy + gr), px(gx + gr, gy - gr)], fill=(200, 235, 200), outline=(40, 140, 40))
        for ax, ay, bx, by, thick in w["walls"]:
            # The face runs a -> b; the solid lies to its right.
            length = math.hypot(bx - ax, by - ay)
            nx, ny = (by - ay) / length * thick, -(bx - ax) / length * thick
            draw.polygon([px(ax, ay), px(bx, by), px(bx + nx, by + ny), px(ax + nx, ay + ny)], fill=(90, 90, 90))
        for cx, cy, r in w["cylinders"]:
            draw.ellipse([px(cx - r, cy + r), px(cx + r, cy - r)], fill=(150, 110, 70))

        truth = self.core.truth()
        rx, ry, rth = truth["pose"]
        mx, my, myaw = w["laser_mount"]
        lx = rx + math.cos(rth) * mx - math.sin(rth) * my
        ly = ry + math.sin(rth) * mx + math.cos(rth) * my
        a0, inc, ranges = self.core.laser_view()
        origin = px(lx, ly)
        for i, r in enumerate(ranges):
            if not math.isfinite(r):
                continue
            a = rth + myaw + a0 + i * inc
            draw.line([origin, px(lx + r * math.cos(a), ly + r * math.sin(a))], fill=(235, 120, 110), width=1)
        rr = w["robot_radius_m"]
        colour = (200, 40, 40) if truth["collided"] else (40, 80, 200)
        draw.ellipse([px(rx - rr, ry + rr), px(rx + rr, ry - rr)], outline=colour, width=2)
        draw.line([px(rx, ry), px(rx + rr * math.cos(rth), ry + rr * math.sin(rth))], fill=colour, width=2)
        return np.asarray(img, dtype=np.uint8)


def _require_pillow():
    try:
        import PIL  # noqa: F401
    except ImportError as exc:
        raise ImportError("render_mode='rgb_array' draws with Pillow, a dependency of b21r_learn "
                          "(tools/python/pyproject.toml) that this environment lacks: "
                          "pip install pillow (or use the project's venv, build/venv)") from exc


def register_envs():
    """Registers every declared task (B21rCorridor-v0, B21rObstacles-v0, ...) with Gymnasium (done on
    import)."""
    for task, env_id in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            # The paper's step limit truncates inside the environment: no TimeLimit wrapper.
            gymnasium.register(id=env_id, entry_point="b21r_learn.envs:B21rEnv", kwargs={"task": task})
