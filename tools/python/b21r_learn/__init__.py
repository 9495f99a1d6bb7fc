# SPDX-License-Identifier: MIT
"""b21r_learn: the RWI B21r tasks of Smart & Kaelbling (ICRA 2002) as Gymnasium environments, and
HEDGER as a Python learner, both computed by the C code the robot runs.

Importing the package registers one environment per declared task (lib/tasks' registry):

- ``B21rCorridor-v0``: corridor following (state: end distance, lateral fraction, target angle);
- ``B21rObstacles-v0``: obstacle avoidance (state: goal bearing and distance, nearest obstacle's
  bearing and distance);
- ``B21rDoorway-v0``: doorway passing (state: wall distance, offset from the door's centre line,
  heading relative to the wall's normal, nearer jamb's distance).

All take ``backend="ode"`` (the emulated B21r: ODE plant, ray-cast LMS200 with noise, rFLEX
protocol; what the controller sees) or ``backend="kinematic"`` (the idealised model, exact state,
fast). See :class:`b21r_learn.envs.B21rEnv`.

The learning framework on any Gymnasium environment (a ``Box`` observation, a one-dimensional
``Box`` action): :class:`Learner` runs lib/learn's two-phase schedule (examples from a policy or
a recorded log, then learned control, evaluation blocks from fixed starts);
``Learner.from_controller_config`` sets it up as the controller does for its own tasks.

HEDGER: :class:`Hedger` (settings as keyword arguments, defaults from the C API), the example
drivers :class:`Driver` (``Driver("proportional", "corridor", gain=1.5)``), and the controller's
files: :func:`read_checkpoint`, :func:`read_checkpoint_progress` (the schedule's progress),
:func:`controller_learner_config`.

Rendering (``render_mode="rgb_array"``) needs Pillow, a dependency of the package
(tools/python/pyproject.toml; the project's venv has it).
"""
from pkgutil import extend_path

# The compiled part (_core) lives in the build tree (<build>/python/b21r_learn), the Python part
# here; extend_path joins every b21r_learn folder on sys.path into this one package. In an
# installed wheel both are in one folder and this changes nothing.
__path__ = extend_path(__path__, __name__)

from ._core import (  # noqa: E402  (after the package path is complete)
    POINT_PROTECTED,
    Driver,
    Hedger,
    HedgerError,
    Prediction,
    controller_learner_config,
    corridor_steps_lower_bound,
    mean_ci95,
    read_checkpoint,
    read_checkpoint_progress,
)
from .envs import B21rEnv, register_envs  # noqa: E402
from .learner import Learner, read_experience_log  # noqa: E402

KIND_NAMES = ("unknown", "lwa", "lwr")  # Prediction.kind / greedy kind -> name

__all__ = [
    "B21rEnv",
    "Driver",
    "Hedger",
    "HedgerError",
    "KIND_NAMES",
    "Learner",
    "POINT_PROTECTED",
    "Prediction",
    "controller_learner_config",
    "corridor_steps_lower_bound",
    "mean_ci95",
    "read_checkpoint",
    "read_checkpoint_progress",
    "read_experience_log",
    "register_envs",
]

register_envs()
