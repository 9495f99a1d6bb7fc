# SPDX-License-Identifier: MIT
"""The two-phase learning framework of Smart & Kaelbling (ICRA 2002) on any Gymnasium environment.

:class:`Learner` drives one agent of ``lib/learn`` (the C library the controller runs; bound as
``b21r_learn._core.Agent``) on an environment with a ``Box`` observation and a one-dimensional
``Box`` action:

1. phase one: examples drive (a callable policy ``example(obs) -> action``, or a recorded log of
   transitions, see :func:`read_experience_log`) while HEDGER learns from every step and replays
   each run backwards;
2. phase two: the learned policy drives (greedy action plus seeded exploration; the example
   advises where nothing is known) and keeps learning;
3. every ``eval_every_runs`` training runs, an evaluation block: learning off, the learned policy
   alone from fixed starts (a list of reset seeds or reset arguments).

The task as the learner sees it comes from the environment: the observation bounds (or scales you
give), the action bounds, the discount you give (``gamma``, default 0.99), the step limit (the
environment's ``TimeLimit`` or ``step_limit``), reward and termination. Settings have the
controller's names and defaults (``b21r-controller --print-reference-config``).
:meth:`Learner.from_controller_config` sets one up exactly as the controller would for its own
task (B21rCorridor-v0, ...): same seeds, start poses, drivers, dither and schedule, so that the same
seed gives the same evaluation blocks as ``b21r-experiment``.
"""
import math
import time

import gymnasium
import numpy as np

from . import _core

SOURCES = ("example", "joystick", "greedy", "exploration", "advisor")  # learn_source_t
_SWITCH = {"runs": 0, "operator": 1, "auto": 2}  # learn_switch_t
_LEARNERS = {"hedger": 0, "lwa": 1, "tabular": 2}  # learn_learner_kind_t
_GREEDY = {"per_action": 0, "state_model": 1}  # hedger_greedy_method_t

# The Learner's settings: controller key -> (learn_config_t field, conversion). Where the
# controller's key has robot units (explore_sigma_radps, explore_hold_s, example_noise_radps) the
# Learner's is in the environment's units (action units, steps) and named without them.
_SETTINGS = {
    "phase_one_runs": ("phase_one_runs", int),
    "phase_two_runs": ("phase_two_runs", int),
    "eval_every_runs": ("eval_every", int),
    "eval_at_start": ("eval_at_start", bool),
    "phase_switch": ("switch_mode", lambda v: _choice(v, _SWITCH, "phase_switch")),
    "auto_switch_min_runs": ("auto_min_runs", int),
    "auto_switch_ratio": ("auto_ratio", float),
    "learner": ("learner", lambda v: _choice(v, _LEARNERS, "learner")),
    "alpha": ("alpha", float),
    "state_last_action": ("state_last_action", bool),
    "last_action_scale": ("last_action_scale", float),
    "hedger_capacity": ("capacity", int),
    "hedger_k_min": ("k_min", int),
    "hedger_k_max": ("k_max", int),
    "hedger_bandwidth": ("bandwidth", float),
    "hedger_merge_radius": ("merge_radius", float),
    "hedger_greedy_actions": ("greedy_actions", int),
    "hedger_greedy_method": ("greedy_method", lambda v: _choice(v, _GREEDY, "hedger_greedy_method")),
    "hedger_greedy_pessimism": ("greedy_pessimism", float),
    "hedger_greedy_reach": ("greedy_reach", float),
    "hedger_replay": ("replay", bool),
    "hedger_replay_passes": ("replay_passes", int),
    "hedger_replay_lambda": ("replay_lambda", float),
    "hedger_replay_alpha": ("replay_alpha", float),
    "hedger_input_scale": ("input_scale", lambda v: [float(x) for x in v]),
    "tabular_bins": ("tabular_bins", int),
    "tabular_actions": ("tabular_actions", int),
    "explore_sigma": ("explore_sigma", float),
    "explore_probability": ("explore_probability", float),
    "explore_hold_steps": ("explore_hold_steps", int),
    "decision_ticks": ("decision_ticks", int),
    "example_noise": ("example_dither_sigma", float),
    "advisor": ("advisor", bool),
    "learn_updates_per_tick": ("replay_updates_per_slice", int),
}


def _choice(value, names, key):
    if isinstance(value, str):
        if value not in names:
            raise ValueError("%s must be one of %s, not %r" % (key, ", ".join(names), value))
        return names[value]
    return int(value)


def controller_defaults():
    """The framework's settings of the controller's default configuration (fw_config_learn_settings
    of b21r-controller's defaults), by learn_config_t field name: the Learner's defaults (those in
    action units as fractions of the robot's +-1 rad/s)."""
    return _core.ControllerTask().learn_settings()


def read_experience_log(path, task_state_dim=None, training_only=True, phase=None):
    """The transitions of a controller's experience log (``--experience-log`` of b21r-controller or
    b21r-experiment, or an lcm-logger file with B21R_EXPERIENCE) as arrays for
    ``Learner(transitions=...)``: ``s``, ``a`` [rad/s], ``r``, ``s_next``, ``terminal`` and ``run``
    (the controller's run id), in log order.

    Also ``step``, ``phase``, ``evaluating``, ``source`` (``SOURCES`` index) and ``q`` (the
    learner's Q(s, a) before the update), as the controller recorded them.

    ``task_state_dim``: the task's features (corridor 3, obstacles 4). A controller with
    ``state_rotation`` (its default) appends the last command sent to its learner's state; that
    column is dropped here (the Learner appends it again from the actions). Default: every column.
    ``training_only``: only training runs' steps (evaluation steps were not learned from);
    ``phase``: only this phase's (1: the examples). Needs the ``lcm`` package and the generated
    B21R types (a build of the project)."""
    import lcm  # noqa: PLC0415 (optional: only for logs)

    try:
        from b21r import experience_t  # noqa: PLC0415
    except ImportError as exc:
        raise ImportError("read_experience_log needs the generated LCM types (package b21r) of a project "
                          "build on sys.path (build/<preset>/python)") from exc
    fingerprint = experience_t._get_packed_fingerprint()
    rows = []
    log = lcm.EventLog(str(path), "r")
    try:
        for ev in log:
            if bytes(ev.data[:8]) != fingerprint:
                continue
            e = experience_t.decode(ev.data)
            if (training_only and e.evaluating) or (phase is not None and e.phase != phase):
                continue
            rows.append(e)
    finally:
        log.close()
    if not rows:
        raise ValueError("%s: no experiences%s" % (path, " of training runs" if training_only else ""))
    dim = rows[0].state_dim if task_state_dim is None else int(task_state_dim)
    if not 1 <= dim <= rows[0].state_dim:
        raise ValueError("task_state_dim must be in 1..%d (the log's state has %d values)"
                         % (rows[0].state_dim, rows[0].state_dim))
    return {
        "s": np.array([e.s[:dim] for e in rows], dtype=np.float64),
        "a": np.array([e.action_radps for e in rows], dtype=np.float64),
        "r": np.array([e.reward for e in rows], dtype=np.float64),
        "s_next": np.array([e.s_next[:dim] for e in rows], dtype=np.float64),
        "terminal": np.array([bool(e.terminal) for e in rows]),
        "run": np.array([e.run_id for e in rows], dtype=np.int64),
        # What else the controller recorded (not needed to learn from the log).
        "step": np.array([e.step_id for e in rows], dtype=np.int64),
        "phase": np.array([e.phase for e in rows], dtype=np.int64),
        "evaluating": np.array([bool(e.evaluating) for e in rows]),
        "source": np.array([e.source for e in rows], dtype=np.int64),
        "q": np.array([e.q_value for e in rows], dtype=np.float64),
    }


def _log_runs(transitions):
    """A recorded log split into runs: a list of (s, a, r, s_next, terminal) index ranges. A run
    ends at a terminal transition, where ``end`` says so, where the run id changes, or where the
    next transition does not start from this one's next state."""
    if isinstance(transitions, (str, bytes)) or hasattr(transitions, "__fspath__"):
        with np.load(transitions) as z:
            transitions = {k: z[k] for k in z.files}
    t = {k: np.asarray(v) for k, v in dict(transitions).items()}
    missing = [k for k in ("s", "a", "r", "s_next", "terminal") if k not in t]
    if missing:
        raise ValueError("transitions: missing %s (need s, a, r, s_next, terminal; optional end, run)"
                         % ", ".join(missing))
    s = np.asarray(t["s"], dtype=np.float64)
    s = s.reshape(len(s), -1)
    n = len(s)
    data = {"s": s, "a": np.asarray(t["a"], dtype=np.float64).reshape(n),
            "r": np.asarray(t["r"], dtype=np.float64).reshape(n),
            "s_next": np.asarray(t["s_next"], dtype=np.float64).reshape(n, -1),
            "terminal": np.asarray(t["terminal"], dtype=bool).reshape(n)}
    end = np.asarray(t["end"], dtype=bool).reshape(n) if "end" in t else np.zeros(n, dtype=bool)
    run = np.asarray(t["run"]).reshape(n) if "run" in t else None
    runs, first = [], 0
    for i in range(n):
        last = (i == n - 1 or data["terminal"][i] or end[i] or (run is not None and run[i + 1] != run[i])
                or not np.array_equal(data["s_next"][i], data["s"][i + 1]))
        if last:
            runs.append((first, i + 1))
            first = i + 1
    # The steps between a run's transitions where the log says (read_experience_log's ``step``):
    # the most common difference, each run's last transition left out (it may end a decision early).
    data["spacing"] = 1
    if "step" in t:
        step = np.asarray(t["step"]).reshape(n)
        gaps = [int(step[i + 1] - step[i]) for a, b in runs for i in range(a, b - 2)]
        if gaps:
            values, counts = np.unique(gaps, return_counts=True)
            data["spacing"] = int(values[np.argmax(counts)])
    return data, runs


def _find_step_limit(env):
    """The environment's step limit: its TimeLimit's, or a B21r task's (it truncates itself)."""
    spec = getattr(env, "spec", None)
    if spec is not None and spec.max_episode_steps:
        return int(spec.max_episode_steps)
    e = env
    while e is not None:
        if isinstance(e, gymnasium.wrappers.TimeLimit):
            return int(e._max_episode_steps)
        e = getattr(e, "env", None)
    task_spec = getattr(env.unwrapped, "task_spec", None)
    if isinstance(task_spec, dict) and task_spec.get("step_limit"):
        return int(task_spec["step_limit"])
    return None


class _ControllerDriver:
    """The example policy of a controller configuration: the task's driver (lib/tasks), begun for
    every run as the controller's loop begins it, acting on the environment's newest state."""

    def __init__(self, controller, env):
        self.controller = controller
        self.base = env.unwrapped
        omega_max = controller.env_limits()["max_rotation_radps"]
        self.driver = _core.Driver("proportional", controller.task_name, omega_max_radps=omega_max)

    def begin_run(self, run):
        self.controller.begin_driver(self.driver, run["run_id"], run["kind"] == "eval", run["phase"])

    def __call__(self, obs):
        return self.base.driver_action(self.driver)


class Learner:
    """The two-phase framework (lib/learn) on a Gymnasium environment.

    Arguments:

    - ``env``: a Gymnasium environment with a ``Box`` observation (at most 7 values) and a ``Box``
      action of shape (1,). Reset and stepped by the Learner only.
    - ``example``: phase one's example policy, ``example(obs) -> action`` (a number or an array of
      one; the observation as the environment returns it). Called on every step of every run (in
      phase two it advises where the learner knows nothing). If it has a ``begin_run(run)``
      method, that is called at the start of each run with a dict (run_id, kind "training" or
      "eval", phase, eval_index, training_index).
    - ``transitions``: a recorded log of examples instead of (or before) the policy: a dict of
      arrays or an ``.npz`` path with ``s`` (N x state), ``a``, ``r``, ``s_next``, ``terminal``
      and optionally ``end`` (the run ended after this transition) and ``run`` (run ids); or
      :func:`read_experience_log` of a controller's log. Each of its runs is one phase-one
      training run (``phase_one_runs`` defaults to their number); the environment is not stepped
      for them. Each transition is learned as one step, so ``decision_ticks`` is 1 with a log
      (given otherwise, refused), and a controller log recorded with ``decision_ticks`` > 1 (its
      ``step`` says so) is refused, naming b21r-train, which learns such logs. A run starts with the last action 0 and ends at a terminal transition, at ``end``,
      where ``run`` changes, or where the next ``s`` is not this ``s_next``.
    - ``seed``: the root of every random stream (exploration and dither, HEDGER's eviction
      generator: the controller's derivation fw_config_derive_seeds; the training resets' seeds).
      Same seed, same environment, same calls: the same results.
    - ``gamma``: the discount per step, [0, 1) (default 0.99).
    - ``state_scale``: per observation value, raw units per scaled unit (HEDGER's distances are
      taken in scaled units; its bandwidth is 0.2 of them). Default: a tenth of the observation
      space's range (required where the space is unbounded).
    - ``action_scale``: action units per scaled unit; default an eighth of the action range (the
      corridor's: 0.25 rad/s of +-1 rad/s).
    - ``greedy_reach``: the task's wider second greedy search where a state has few neighbours
      (>= 1; the corridor declares 8, the obstacle task 3); default 3.
    - ``step_limit``: a run ends after this many actions (truncated). Default: the environment's
      ``TimeLimit`` (or a B21r task's own step limit). A run that misses the goal counts at it.
    - ``eval_starts``: the evaluation block's fixed starts: a list (at most 16) of reset seeds
      (int) or reset keyword arguments (dict, e.g. ``{"seed": 3, "options": {...}}``). Default:
      seeds 0..9.
    - ``train_starts``: the training runs' resets: None (seeds drawn from ``seed``), a list
      (cycled) of seeds or reset dicts, or a callable ``(training_index) -> reset dict``.
    - ``success``: ``success(obs, reward, terminated, truncated, info) -> bool``: did the run reach
      its goal (evaluation blocks count these). Default: ``terminated`` (for a B21r environment:
      ``info["reason"] == "goal"``). Give it where a termination is a failure.
    - ``env_seed``: a seed for the first reset only (the B21r environments' emulator).
    - ``task`` / ``learn_config``: learn_task_t / learn_config_t fields by their C names, applied
      last (any field of lib/learn, including ones this class has no keyword for).
    - ``record_experiences``: keep every learned (or, evaluating, predicted) step in
      :attr:`experiences`, as the controller's B21R_EXPERIENCE records them: dicts with run_id,
      step_id, phase, evaluating, source, s and s_next (the learner's state), a, v, reward,
      terminal, q (Q(s, a) before the update) and q_kind.

    Settings (keyword arguments, the controller's keys and defaults; see
    ``b21r-controller --print-reference-config``):

    - schedule: ``phase_one_runs`` (30), ``phase_two_runs`` (35), ``eval_every_runs`` (5),
      ``eval_at_start`` (False), ``phase_switch`` ("runs", "operator" or "auto"),
      ``auto_switch_min_runs``, ``auto_switch_ratio``;
    - learner: ``learner`` ("hedger", "lwa", "tabular"), ``alpha`` (0.2), ``state_last_action``
      (the controller's ``state_rotation``, True: the learner's state ends with the last action
      sent, 0 at a run's start), ``last_action_scale`` (action units per scaled unit; half the
      action range, as the controller's 1 rad/s of +-1 rad/s),
      ``hedger_capacity`` (20000 points), ``hedger_k_min``, ``hedger_k_max``, ``hedger_bandwidth``
      (scaled units), ``hedger_merge_radius``, ``hedger_greedy_actions``,
      ``hedger_greedy_method`` ("state_model", "per_action"), ``hedger_greedy_pessimism``,
      ``hedger_greedy_reach`` (0: the task's), ``hedger_replay``, ``hedger_replay_passes``,
      ``hedger_replay_lambda``, ``hedger_replay_alpha`` (0: alpha), ``hedger_input_scale``
      (overrides the scales: state, last action, action), ``tabular_bins``, ``tabular_actions``;
    - acting: ``explore_sigma`` (phase two's exploration offset, standard deviation in action
      units; the controller's explore_sigma_radps, 0.1 rad/s of +-1 rad/s: default 0.05 of the
      action range), ``explore_probability`` (per training decision, the chance a segment
      starts; 0.2), ``explore_hold_steps`` (a segment's length in decisions; the controller's
      explore_hold_s / (tick period x decision_ticks): 1), ``decision_ticks`` (the policy and the
      example decide every this many steps, each decision learned as one step of gamma^N; on the
      B21r environments the controller's 2, their step being its 0.1 s tick; elsewhere 1),
      ``example_noise`` (phase one's dither offset, action units; the controller's
      example_noise_radps, 0.3 rad/s: default 0.15 of the action range),
      ``advisor`` (True: in phase two's training runs the example's action where the learner
      knows none);
    - ``learn_updates_per_tick``: backward-replay updates per slice between runs (the results do
      not depend on it).

    Results. :meth:`run` returns :attr:`blocks`, one dict per evaluation block: block, phase,
    training_runs (completed before it), n_starts, steps and success per start (a run that missed
    the goal counts at the step limit), successes, failures, mean_steps over the successful runs
    with its Student-t 95 % ci95_halfwidth (the controller's numbers), mean_return over all its
    runs, store_fill. :attr:`runs`: one dict per run: run_id, kind ("training", "eval"), phase,
    training_index / eval_index, steps (actions), return (summed reward), goal, outcome ("goal",
    "terminal", "step_limit"), from_log, sources (steps by who chose the action: example,
    joystick, greedy, exploration, advisor), store_fill (after its replay). :attr:`wall_time_s`:
    time spent in :meth:`run`.
    """

    def __init__(self, env, example=None, *, transitions=None, seed=0, gamma=0.99, state_scale=None,
                 action_scale=None, greedy_reach=3.0, step_limit=None, eval_starts=None, train_starts=None,
                 success=None, env_seed=None, task=None, learn_config=None, record_experiences=False, **settings):
        self.env = env
        self.example = example
        self.seed = int(seed)
        self._b21r = _is_b21r(env)
        # Actions go out in the action space's dtype (the executed action is that value), except to
        # a B21r environment: it computes in double precision, as the controller's commands are.
        self._action_dtype = np.float64 if self._b21r else env.action_space.dtype
        self._success = success
        self._env_seed = env_seed
        self._train_starts = train_starts
        self._eval_starts = list(range(10)) if eval_starts is None else list(eval_starts)
        if not 1 <= len(self._eval_starts) <= _core.LEARN_SCHEDULE_MAX_STARTS:
            raise ValueError("eval_starts: 1 to %d starts" % _core.LEARN_SCHEDULE_MAX_STARTS)
        self._log, self._log_runs = (None, []) if transitions is None else _log_runs(transitions)

        learn_task = self._task_from_env(gamma, state_scale, action_scale, greedy_reach, step_limit)
        learn_task.update(task or {})
        self.step_limit = int(learn_task["step_limit"])

        config = controller_defaults()
        if not self._b21r:
            # The controller's decision_ticks is for its 0.1 s tick, which the B21r environments'
            # step is; another environment's step is its own choice: a decision every step.
            config["decision_ticks"] = 1
        _, explore_seed, learner_seed, _ = _core.controller_seeds(self.seed)
        config.update(explore_seed=explore_seed, learner_seed=learner_seed, eval_starts=len(self._eval_starts),
                      input_scale=[])
        # The controller's settings in action units (rad/s of a +-1 rad/s range) become the same
        # fractions of this action range: the last action's scale, the exploration and the dither.
        half_range = 0.5 * (learn_task["action_max"] - learn_task["action_min"])
        for field in ("last_action_scale", "explore_sigma", "example_dither_sigma"):
            config[field] *= half_range
        if self._log_runs and "phase_one_runs" not in settings:
            config["phase_one_runs"] = len(self._log_runs)
        for key, value in settings.items():
            if key not in _SETTINGS:
                raise TypeError("Learner: unknown setting %r (known: %s)" % (key, ", ".join(sorted(_SETTINGS))))
            field, convert = _SETTINGS[key]
            config[field] = convert(value)
        config.update(learn_config or {})
        if self._log_runs:
            # A log is replayed one step per transition, so its runs are learned with decisions of
            # one step; a log of decisions held over N steps is b21r-train's (it learns each as one).
            if "decision_ticks" not in settings and "decision_ticks" not in (learn_config or {}):
                config["decision_ticks"] = 1
            if config["decision_ticks"] > 1:
                raise ValueError("transitions: a log is replayed one step per transition, so decision_ticks must be 1, "
                                 "not %d: give decision_ticks=1 (a controller configuration's: settings={..., "
                                 "\"decision_ticks\": 1})" % config["decision_ticks"])
            if self._log["spacing"] > 1:
                raise ValueError("transitions: the log's transitions are %d steps apart (recorded with decision_ticks = "
                                 "%d: one per decision); the Learner replays steps. Train from such a log with "
                                 "b21r-train --set decision_ticks=%d" % ((self._log["spacing"],) * 3))
        if config["eval_starts"] > len(self._eval_starts):
            raise ValueError("eval_starts: the schedule's blocks have %d starts, %d given"
                             % (config["eval_starts"], len(self._eval_starts)))
        if (self.example is None and config["mode"] == 0
                and config["phase_one_runs"] > len(self._log_runs) and config["switch_mode"] != 1):
            raise ValueError("phase one has %d runs but no example policy drives them (give example=, or "
                             "transitions= with as many runs)" % config["phase_one_runs"])
        self.agent = _core.Agent(learn_task, config)
        self._first_reset = True
        self.runs = []
        self.blocks = []
        self.experiences = [] if record_experiences else None
        self.wall_time_s = 0.0

    # ---- set-up ----------------------------------------------------------------------------

    @classmethod
    def from_controller_config(cls, settings=None, config_file=None, env=None, backend="ode", transitions=None,
                               record_experiences=False, **env_kwargs):
        """A Learner set up as the controller sets up its own learning for the configuration
        ``settings`` (controller keys, e.g. ``{"task": "corridor", "seed": 1, "phase_two_runs": 5}``),
        optionally over ``config_file`` (a controller config or experiment file; its
        ``experiment.*`` keys are skipped): the task and the framework's settings
        (fw_config_learn_task, fw_config_learn_settings), the seeds (fw_config_derive_seeds), the
        training start poses (drawn from the controller's pose stream), the evaluation poses, the
        task's driver for each run (seeded per run id, kind and gain as the loop sets them) and
        the environment's emulator seeded with the configuration's seed. On the ODE back-end the
        evaluation blocks (and every run) equal b21r-experiment's for the same configuration and
        seed (test/python/test_learner_controller.py).

        ``env``: the task's environment with the configuration's specification and command limits
        (default: made here with ``backend`` "ode" or "kinematic" and ``env_kwargs``, e.g.
        ``render_mode="rgb_array"``; one given is checked against the configuration). ``transitions``: phase one's examples from a log instead of the task's
        driver (see :class:`Learner` and :func:`read_experience_log`). ``record_experiences``: as
        for :class:`Learner`. The
        :class:`b21r_learn._core.ControllerTask` is kept as ``learner.controller``."""
        ct = _core.ControllerTask(dict(settings or {}), None if config_file is None else str(config_file))
        if env is None:
            env = gymnasium.make(ct.env_id, backend=backend, spec=ct.env_spec(), limits=ct.env_limits(), **env_kwargs)
        base = env.unwrapped
        if not _is_b21r(env) or base.task != ct.task_name:
            raise ValueError("from_controller_config: env must be the %s task's environment (%s)"
                             % (ct.task_name, ct.env_id))
        spec, want = base.task_spec, ct.env_spec()
        differ = [k for k in want if k in spec and not _same(spec[k], want[k])]
        differ += [k for k, v in ct.env_limits().items() if not _same(spec["limits"][k], v)]
        if differ:
            raise ValueError("from_controller_config: the environment's %s differ from the configuration's: leave "
                             "env out to have it made, or make it with spec= and limits= of "
                             "b21r_learn._core.ControllerTask(settings).env_spec() and .env_limits()"
                             % ", ".join(differ))
        poses = ct.eval_starts()
        learner = cls(env, _ControllerDriver(ct, env), transitions=transitions, seed=ct.seed, env_seed=ct.seed,
                      eval_starts=[{"options": {"pose": p}} for p in poses],
                      train_starts=lambda index: {"options": {"pose": ct.training_start()}},
                      task=ct.learn_task(), learn_config=ct.learn_settings(), record_experiences=record_experiences)
        learner.controller = ct
        return learner

    def _task_from_env(self, gamma, state_scale, action_scale, greedy_reach, step_limit):
        obs_space, act_space = self.env.observation_space, self.env.action_space
        if not isinstance(obs_space, gymnasium.spaces.Box) or len(obs_space.shape) != 1:
            raise ValueError("the observation space must be a 1-D Box, not %r" % (obs_space,))
        dim = obs_space.shape[0]
        if not 1 <= dim <= _core.LEARN_MAX_TASK_STATE:
            raise ValueError("the observation has %d values; lib/learn takes 1..%d"
                             % (dim, _core.LEARN_MAX_TASK_STATE))
        if not isinstance(act_space, gymnasium.spaces.Box) or act_space.shape not in ((1,), ()):
            raise ValueError("the action space must be a Box of one value, not %r" % (act_space,))
        low = np.asarray(obs_space.low, dtype=np.float64)
        high = np.asarray(obs_space.high, dtype=np.float64)
        finite = np.isfinite(low) & np.isfinite(high)
        if state_scale is None:
            if not finite.all():
                raise ValueError("the observation space is unbounded in %s: give state_scale (raw units per "
                                 "scaled unit, one per value)" % list(np.flatnonzero(~finite)))
            state_scale = (high - low) / 10.0
        state_scale = np.broadcast_to(np.asarray(state_scale, dtype=np.float64), (dim,))
        if not (np.isfinite(state_scale).all() and (state_scale > 0).all()):
            raise ValueError("state_scale must be finite and > 0, got %s" % list(state_scale))
        # The declared range (the tabular learner's bins): the space's, or +-5 scaled units.
        low = np.where(finite, low, -5.0 * state_scale)
        high = np.where(finite, high, 5.0 * state_scale)
        a_low, a_high = float(np.min(act_space.low)), float(np.max(act_space.high))
        if not (math.isfinite(a_low) and math.isfinite(a_high) and a_low < a_high):
            raise ValueError("the action space needs finite bounds low < high")
        self.action_low, self.action_high = a_low, a_high
        if step_limit is None:
            step_limit = _find_step_limit(self.env)
            if step_limit is None:
                raise ValueError("the environment declares no step limit (TimeLimit): give step_limit")
        return {"state_dim": dim, "state_scale": list(state_scale), "state_min": list(low), "state_max": list(high),
                "action_min": a_low, "action_max": a_high,
                "action_scale": float(action_scale) if action_scale is not None else (a_high - a_low) / 8.0,
                "gamma": float(gamma), "step_limit": int(step_limit), "greedy_reach": float(greedy_reach)}

    # ---- the schedule ----------------------------------------------------------------------

    @property
    def config(self):
        """The framework's settings in use (learn_config_t fields)."""
        return self.agent.config

    @property
    def task(self):
        """The task as the learner sees it (learn_task_t fields)."""
        return self.agent.task

    def run(self, max_runs=None, on_run=None):
        """Runs the schedule to its end (or ``max_runs`` more runs) and returns the evaluation
        blocks so far (see :attr:`blocks`). ``on_run(run, block)`` is called after every run with
        its record (see :attr:`runs`) and, when the run completed an evaluation block, that block
        (else None)."""
        t0 = time.perf_counter()
        done = 0
        while max_runs is None or done < max_runs:
            plan = self.agent.plan()
            if plan["kind"] == "none":
                break
            record, block = self._one_run(plan)
            done += 1
            if on_run is not None:
                on_run(record, block)
        self.wall_time_s += time.perf_counter() - t0
        return self.blocks

    @property
    def done(self):
        """True when the schedule has ended."""
        return self.agent.plan()["kind"] == "none"

    def _reset_kwargs(self, plan):
        if plan["kind"] == "eval":
            start = self._eval_starts[plan["eval_index"]]
        elif self._train_starts is None:
            start = int(np.random.SeedSequence([self.seed, 1, plan["training_index"]]).generate_state(1)[0])
        elif callable(self._train_starts):
            start = self._train_starts(plan["training_index"])
        else:
            start = self._train_starts[plan["training_index"] % len(self._train_starts)]
        kwargs = {"seed": int(start)} if isinstance(start, (int, np.integer)) else dict(start)
        if self._first_reset and self._env_seed is not None:
            kwargs.setdefault("seed", self._env_seed)
        return kwargs

    def _one_run(self, plan):
        agent = self.agent
        log_run = plan["kind"] == "training" and plan["phase"] == 1 and plan["training_index"] < len(self._log_runs)
        run = {"run_id": agent.run_id + 1, "kind": plan["kind"], "phase": plan["phase"],
               "eval_index": plan["eval_index"], "training_index": plan["training_index"]}
        if log_run:
            end = self._log_run(*self._log_runs[plan["training_index"]])
        else:
            end = self._env_run(run)
        # Between runs: the last update and the backward replay, in the framework's slices.
        while not agent.idle():
            self._after_command()
        record = {"run_id": end["run_id"], "kind": plan["kind"], "phase": plan["phase"],
                  "training_index": plan["training_index"] if plan["kind"] == "training" else -1,
                  "eval_index": plan["eval_index"] if plan["kind"] == "eval" else -1,
                  "steps": end["steps"], "return": end["total_reward"], "goal": end["goal"],
                  "outcome": end["outcome"], "from_log": log_run,
                  "sources": dict(zip(SOURCES, end["steps_by_source"])), "store_fill": agent.stats()["fill"]}
        self.runs.append(record)
        block = end["block"]
        if block is not None:
            rets = [r["return"] for r in self.runs if r["kind"] == "eval"][-block["n_starts"]:]
            block["mean_return"] = float(np.mean(rets))
            block["failures"] = block["n_starts"] - block["successes"]
            block["store_fill"] = record["store_fill"]
            self.blocks.append(block)
        return record, block

    def _env_run(self, run):
        agent, env = self.agent, self.env
        obs, info = env.reset(**self._reset_kwargs(run))
        self._first_reset = False
        if self.example is not None and hasattr(self.example, "begin_run"):
            self.example.begin_run(run)
        agent.begin_run()
        features = _vec(obs)
        if not agent.observe(features, 0.0):
            raise ValueError("the first observation is not finite: %s" % (features,))
        dtype, shape = self._action_dtype, env.action_space.shape
        step_limit = self.step_limit
        while True:
            advice = float(np.reshape(self.example(obs), -1)[0]) if self.example is not None else 0.0
            action, _ = agent.act(advice, 0.0)
            if not self._b21r:  # a B21r environment clamps the command itself, as the controller does
                action = min(max(action, self.action_low), self.action_high)
            sent = np.full(shape, action, dtype=dtype)
            obs, reward, terminated, truncated, info = env.step(sent)
            if self._b21r:
                executed, translation = info["action"], info["translation_mps"]
            else:
                executed, translation = float(sent.reshape(-1)[0]), 0.0
            agent.executed(executed, translation)
            self._after_command()
            features = _vec(obs)
            if not agent.observe(features, executed):
                raise ValueError("the environment returned a non-finite observation: %s" % (features,))
            cut = truncated or (step_limit > 0 and agent.run_actions() >= step_limit)
            goal = self._is_success(obs, reward, terminated, cut, info)
            reason = _B21R_REASONS.index(info["reason"]) if self._b21r else _reason(terminated, cut, goal)
            end = agent.transition(float(reward), bool(terminated), bool(terminated or cut), bool(goal), reason)
            if end is not None:
                end["outcome"] = "goal" if goal else ("terminal" if terminated else "step_limit")
                return end

    def _log_run(self, first, last):
        agent, d = self.agent, self._log
        if d["s"].shape[1] != agent.task["state_dim"]:
            raise ValueError("transitions: states of %d values, the task's have %d"
                             % (d["s"].shape[1], agent.task["state_dim"]))
        agent.begin_run()
        agent.observe(d["s"][first], 0.0)
        for i in range(first, last):
            a = float(d["a"][i])
            agent.act(a, 0.0)  # phase one: the log's action is the example's
            agent.executed(a, 0.0)
            self._after_command()
            agent.observe(d["s_next"][i], a)
            terminal = bool(d["terminal"][i])
            goal = self._is_success(d["s_next"][i], d["r"][i], terminal, not terminal, {})
            end = agent.transition(float(d["r"][i]), terminal, i == last - 1, bool(goal),
                                   _reason(terminal, i == last - 1, goal))
            if end is not None:
                end["outcome"] = "goal" if goal else ("terminal" if terminal else "step_limit")
                return end
        raise AssertionError("a log run ended without its last transition")  # pragma: no cover

    def _after_command(self):
        # The step's update (or, evaluating, the prediction of its Q) or a slice of the replay.
        if self.agent.after_command() and self.experiences is not None:
            self.experiences.append(self.agent.experience())

    def _is_success(self, obs, reward, terminated, truncated, info):
        if self._success is not None:
            return bool(self._success(obs, reward, terminated, truncated, info))
        if self._b21r:
            return info.get("reason") == "goal"
        return bool(terminated)

    # ---- the learned policy ----------------------------------------------------------------

    def policy(self, obs, last_action=0.0):
        """The learned policy's action for an observation (``last_action``: the action sent before
        it, 0 at a run's start; used when the learner's state holds it), as in evaluations: the
        greedy action, 0 where nothing is known. Queries only (nothing is learned)."""
        action, _, known = self.agent.greedy(self._learner_state(obs, last_action))
        return min(max(action, self.action_low), self.action_high) if known else 0.0

    def value(self, obs, action, last_action=0.0):
        """(Q(s, a), kind) of the learned values: kind 0 unknown, 1 LWA, 2 LWR."""
        return self.agent.predict(self._learner_state(obs, last_action), float(action))

    def _learner_state(self, obs, last_action):
        s = _vec(obs)
        return np.append(s, float(last_action)) if self.agent.state_dim > len(s) else s

    def evaluate(self, policy=None, starts=None):
        """One evaluation block outside the schedule (nothing learned, nothing counted): ``policy``
        (``policy(obs) -> action``; default: the learned policy, as in the schedule's blocks) from
        ``starts`` (default: the evaluation starts). Returns a dict: steps and success per start,
        successes, mean_steps (over successes) with its 95 % half-width, mean_return, failures."""
        starts = self._eval_starts if starts is None else list(starts)
        steps, success, returns = [], [], []
        for start in starts:
            kwargs = {"seed": int(start)} if isinstance(start, (int, np.integer)) else dict(start)
            obs, info = self.env.reset(**kwargs)
            last, total, n, goal = 0.0, 0.0, 0, False
            while True:
                a = self.policy(obs, last) if policy is None else float(np.reshape(policy(obs), -1)[0])
                a = min(max(a, self.action_low), self.action_high)
                sent = np.full(self.env.action_space.shape, a, dtype=self._action_dtype)
                obs, reward, terminated, truncated, info = self.env.step(sent)
                last = info["action"] if self._b21r else float(sent.reshape(-1)[0])
                total += float(reward)
                n += 1
                cut = truncated or (self.step_limit > 0 and n >= self.step_limit)
                if terminated or cut:
                    goal = self._is_success(obs, reward, terminated, cut, info)
                    break
            steps.append(n if goal else self.step_limit)
            success.append(bool(goal))
            returns.append(total)
        mean, half = _core.mean_ci95([float(s) for s, ok in zip(steps, success) if ok])
        return {"steps": steps, "success": success, "successes": int(sum(success)), "mean_steps": mean,
                "ci95_halfwidth": half, "mean_return": float(np.mean(returns)),
                "failures": len(starts) - int(sum(success)), "n_starts": len(starts)}

    def save(self):
        """HEDGER's learned state as bytes (the controller's checkpoint payload format;
        ``b21r_learn.Hedger(**learner.agent.learner_config).load(...)`` reads it)."""
        return self.agent.save()


def _is_b21r(env):
    from .envs import B21rEnv  # noqa: PLC0415 (envs imports this module's package)

    return isinstance(env.unwrapped, B21rEnv)


def _same(a, b):
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _vec(obs):
    return np.ascontiguousarray(obs, dtype=np.float64).reshape(-1)


# A B21r environment's info["reason"] values, in the order of tasks_end_reason_t.
_B21R_REASONS = ("none", "goal", "collision", "step_limit")


def _reason(terminal, cut, goal):
    # The end reason kept in the experience (as tasks_end_reason_t numbers them): goal 1, another
    # terminal state 2, the step limit 3, none 0.
    return 1 if goal else (2 if terminal else (3 if cut else 0))
