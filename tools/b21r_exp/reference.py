# SPDX-License-Identifier: MIT
"""Reference learners: standard reinforcement learners from scratch on the product's Gymnasium
environments (b21r_learn: B21rCorridor-v0, B21rObstacles-v0), the yardstick a user would pick
instead of the product's learner. Stable-Baselines3's SAC, PPO and TD3 train on the environment
with no examples and are evaluated the way the product's evaluation blocks are: deterministic
policy, the task's 10 evaluation poses, mean steps to the goal with failures counted at the step
limit, successes of 10, beside the optimal controller from the same poses.

An experiment file of this kind (tools/experiments/reference_learners.conf) has the format of the
other experiment files (KEY = VALUE, # comments) with `experiment.kind = reference` and these keys:

  experiment.name, experiment.title, experiment.seeds, experiment.first_seed, experiment.vary
      as for b21r-experiment (the axis is one reference.* key)
  experiment.on_request   true: the sweep runs it only when it is named (default false)
  reference.algorithm     sac | ppo | td3
  reference.env           B21rCorridor-v0 | B21rObstacles-v0
  reference.backend       kinematic (the idealised model) | ode (the emulated B21r)
  reference.train_steps_sac, reference.train_steps_ppo, reference.train_steps_td3
                          environment steps of training, per algorithm
  reference.eval_every_steps
                          an evaluation after every this many training steps (and one before
                          training)

Hyperparameters: Stable-Baselines3's defaults for each algorithm ("MlpPolicy"), with one
addition for TD3, whose default has no exploration noise at all: Gaussian action noise of
standard deviation 0.1 x the action bound (Stable-Baselines3's documented example). The values in
force are read back from the model into the result file.

Determinism: one torch thread, torch.use_deterministic_algorithms(True), the model, the training
environment and its action space seeded with the seed; the evaluation runs draw nothing from the
learner's generators (the deterministic policy is the distribution's mode), so evaluating changes
nothing in training. Every evaluation run resets the evaluation environment with the seed, so
every evaluation block of a seed (and the optimal controller's) sees the same emulator noise.

Step counting: training steps are the training environment's steps (Stable-Baselines3's
num_timesteps with one environment); evaluation steps are not counted. Per evaluation the result
records the training steps and the training episodes so far, and how many of those ended on a
wall (info["reason"] == "collision").

Command (the sweep's Ray tasks run it; by hand from the repository root):
  build/venv/bin/python3 -m b21r_exp.reference --config FILE --seed N [--variant KEY=VALUE]
      --out RESULT.json [--verbose]         (PYTHONPATH=tools)
  ... --config FILE --plan                  the experiment's plan as JSON
"""
import argparse
import hashlib
import json
import os
import sys
import time

FORMAT = "b21r-experiment-result/1"
KIND = "reference"
ALGORITHMS = ("sac", "ppo", "td3")
ENVS = {"B21rCorridor-v0": "corridor", "B21rObstacles-v0": "obstacles"}
BACKENDS = ("kinematic", "ode")
TD3_NOISE_SIGMA = 0.1  # x the action bound

DEFAULTS = {
    "experiment.name": "",
    "experiment.title": "",
    "experiment.kind": KIND,
    "experiment.seeds": "10",
    "experiment.first_seed": "1",
    "experiment.vary": "",
    "experiment.on_request": "false",
    "reference.algorithm": "sac",
    "reference.env": "B21rCorridor-v0",
    "reference.backend": "kinematic",
    "reference.train_steps_sac": "20000",
    "reference.train_steps_ppo": "50000",
    "reference.train_steps_td3": "20000",
    "reference.eval_every_steps": "1000",
}


class ConfigError(ValueError):
    pass


def _int(v, lo, hi, where):
    try:
        x = int(v)
    except ValueError:
        raise ConfigError("%s: '%s' is not an integer" % (where, v)) from None
    if not lo <= x <= hi:
        raise ConfigError("%s: %d is not in [%d, %d]" % (where, x, lo, hi))
    return x


def _check(key, value, where):
    """Checks one value; returns it converted."""
    if key in ("experiment.seeds",):
        return _int(value, 1, 1000, where)
    if key == "experiment.first_seed":
        return _int(value, 1, 1000000, where)
    if key.startswith("reference.train_steps_"):
        return _int(value, 1, 100000000, where)
    if key == "reference.eval_every_steps":
        return _int(value, 1, 100000000, where)
    if key == "experiment.on_request":
        if value not in ("true", "false"):
            raise ConfigError("%s: '%s' is not true or false" % (where, value))
        return value == "true"
    choices = {"experiment.kind": (KIND,), "reference.algorithm": ALGORITHMS, "reference.env": tuple(ENVS),
               "reference.backend": BACKENDS}.get(key)
    if choices and value not in choices:
        raise ConfigError("%s: '%s' is not one of %s" % (where, value, ", ".join(choices)))
    if len(value) > 255:
        raise ConfigError("%s: longer than 255 characters" % where)
    return value


def read_pairs(path):
    """[(line number, key, value)] of an experiment file (KEY = VALUE, # comments, "quotes")."""
    out = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            if "=" not in line:
                raise ConfigError("%s:%d: expected KEY = VALUE" % (path, n))
            k, v = line.split("=", 1)
            v = v.strip()
            if len(v) >= 2 and v[0] == v[-1] == '"':
                v = v[1:-1]
            out.append((n, k.strip(), v))
    return out


def is_reference(path):
    """True when the experiment file at path is of this kind (experiment.kind = reference)."""
    try:
        return any(k == "experiment.kind" and v == KIND for _, k, v in read_pairs(path))
    except (OSError, ConfigError):
        return False


def load_config(path, variant=""):
    """The experiment's settings (DEFAULTS overridden by the file, then by the variant
    KEY=VALUE), each checked; an unknown key or a bad value is refused with file:line."""
    raw = dict(DEFAULTS)
    where = {}
    for n, k, v in read_pairs(path):
        w = "%s:%d: %s" % (path, n, k)
        if k not in DEFAULTS:
            raise ConfigError("%s:%d: unknown key '%s' (known: %s)" % (path, n, k, ", ".join(sorted(DEFAULTS))))
        _check(k, v, w)
        raw[k] = v
        where[k] = w
    axis, values = vary_axis(raw["experiment.vary"], where.get("experiment.vary", path))
    if variant:
        if "=" not in variant:
            raise ConfigError("variant '%s': expected KEY=VALUE" % variant)
        k, v = variant.split("=", 1)
        if k != axis or v not in values:
            raise ConfigError("variant '%s' is not one of the file's (%s)" % (
                variant, ", ".join("%s=%s" % (axis, x) for x in values) or "none"))
        raw[k] = v
    cfg = {k: _check(k, v, where.get(k, k)) for k, v in raw.items()}
    cfg["experiment.name"] = cfg["experiment.name"] or os.path.basename(path)[: -len(".conf")]
    return cfg


def vary_axis(vary, where):
    """(key, [values]) of experiment.vary, or ("", [])."""
    if not vary:
        return "", []
    if "=" not in vary:
        raise ConfigError("%s: expected KEY=V1|V2|..." % where)
    k, vs = vary.split("=", 1)
    k = k.strip()
    values = [x.strip() for x in vs.split("|")]
    if k not in DEFAULTS or not k.startswith("reference."):
        raise ConfigError("%s: the axis must be a reference.* key, not '%s'" % (where, k))
    if len(set(values)) != len(values) or not all(values):
        raise ConfigError("%s: empty or repeated values" % where)
    for v in values:
        _check(k, v, "%s (variant %s=%s)" % (where, k, v))
    return k, values


def plan(path, seeds=None):
    """The plan the sweep uses (as b21r-experiment --plan): name, kind, title, seeds, variants."""
    cfg = load_config(path)
    axis, values = vary_axis(cfg["experiment.vary"], path)
    first = cfg["experiment.first_seed"]
    n = cfg["experiment.seeds"] if seeds is None else seeds
    return {"name": cfg["experiment.name"], "kind": KIND, "title": cfg["experiment.title"],
            "seeds": list(range(first, first + n)),
            "variants": ["%s=%s" % (axis, v) for v in values] or [""],
            "on_request": cfg["experiment.on_request"]}


def versions():
    """Versions of the packages a result depends on."""
    import gymnasium
    import numpy
    import stable_baselines3
    import torch

    return {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
            "gymnasium": gymnasium.__version__, "numpy": numpy.__version__,
            "python": "%d.%d.%d" % sys.version_info[:3]}


def build_id():
    """The identity of the program that makes a result: this file, the packages' versions and the
    compiled environment (b21r_learn's C core), first 16 hex digits of their SHA-256."""
    import b21r_learn

    h = hashlib.sha256()
    with open(os.path.abspath(__file__), "rb") as f:
        h.update(f.read())
    h.update(json.dumps(versions(), sort_keys=True).encode())
    with open(b21r_learn._core.__file__, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return "ref-" + h.hexdigest()[:16]


# ---- evaluation ---------------------------------------------------------------------------------


def run_episode(env, seed, index, act):
    """One evaluation run from evaluation pose index; returns (steps, reached the goal). A run
    that does not reach the goal counts at the step limit."""
    obs, _ = env.reset(seed=seed, options={"start": "eval", "eval_index": index})
    limit = env.unwrapped.task_spec["step_limit"]
    while True:
        obs, _, terminated, truncated, info = env.step(act(obs))
        if terminated or truncated:
            goal = info["reason"] == "goal"
            return (info["steps"] if goal else limit), goal


def evaluate(env, seed, act_for_pose):
    """The 10 evaluation poses: {"steps": [...], "success": [...], "mean_all", "successes"}."""
    import b21r_learn

    steps, success = [], []
    for i in range(b21r_learn._core.N_EVAL_STARTS):
        n, ok = run_episode(env, seed, i, act_for_pose(i))
        steps.append(int(n))
        success.append(bool(ok))
    return {"steps": steps, "success": success, "mean_all": sum(steps) / len(steps), "successes": sum(success)}


def optimal_for_pose(env, task):
    import b21r_learn
    import numpy as np

    driver = b21r_learn.Driver("optimal", task)

    def for_pose(i):
        driver.begin_run(i)
        return lambda obs: np.array([env.unwrapped.driver_action(driver)])

    return for_pose


# ---- training -----------------------------------------------------------------------------------


def hyperparameters(model, algorithm):
    """The hyperparameters in force, read back from the model (JSON-able)."""
    names = {"sac": ("learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "train_freq",
                     "gradient_steps", "ent_coef", "target_update_interval", "target_entropy", "use_sde"),
             "td3": ("learning_rate", "buffer_size", "learning_starts", "batch_size", "tau", "gamma", "train_freq",
                     "gradient_steps", "policy_delay", "target_policy_noise", "target_noise_clip"),
             "ppo": ("learning_rate", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "clip_range",
                     "ent_coef", "vf_coef", "max_grad_norm", "normalize_advantage", "use_sde")}[algorithm]
    out = {}
    for n in names:
        v = getattr(model, n, None)
        if callable(v):  # schedules (learning rate, clip range): their value at the start
            v = v(1.0)
        if hasattr(v, "item"):
            v = v.item()
        out[n] = v if isinstance(v, (int, float, str, bool, type(None))) else str(v)
    out["policy"] = "MlpPolicy"
    out["net_arch"] = str(model.policy.net_arch) if hasattr(model.policy, "net_arch") else None
    if algorithm == "td3":
        out["action_noise"] = "Normal(0, %g x action bound)" % TD3_NOISE_SIGMA
    return out


def train(cfg, seed, log=None):
    """Trains the configured learner for one seed; returns the result's "reference" part."""
    import gymnasium
    import numpy as np
    import torch
    from stable_baselines3 import PPO, SAC, TD3
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.noise import NormalActionNoise

    import b21r_learn  # noqa: F401 (registers the environments)

    torch.set_num_threads(1)
    try:
        torch.use_deterministic_algorithms(True)
    except RuntimeError:  # pragma: no cover
        pass
    algorithm = cfg["reference.algorithm"]
    env_id = cfg["reference.env"]
    backend = cfg["reference.backend"]
    task = ENVS[env_id]
    steps_total = cfg["reference.train_steps_" + algorithm]
    every = cfg["reference.eval_every_steps"]
    t0 = time.time()

    episodes = []  # training episodes: steps and reason

    class Recorder(gymnasium.Wrapper):
        """Counts the training environment's steps and records how each episode ended."""

        def step(self, action):
            out = super().step(action)
            if out[2] or out[3]:
                episodes.append({"steps": int(out[4]["steps"]), "reason": out[4]["reason"]})
            return out

    train_env = Recorder(gymnasium.make(env_id, backend=backend))
    eval_env = gymnasium.make(env_id, backend=backend)
    bound = float(train_env.action_space.high[0])
    kwargs = {"seed": seed, "device": "cpu", "verbose": 0}
    if algorithm == "td3":
        kwargs["action_noise"] = NormalActionNoise(np.zeros(1), np.full(1, TD3_NOISE_SIGMA * bound))
    model = {"sac": SAC, "ppo": PPO, "td3": TD3}[algorithm]("MlpPolicy", train_env, **kwargs)

    optimal = evaluate(eval_env, seed, optimal_for_pose(eval_env, task))
    evaluations = []

    def evaluate_policy(num_timesteps):
        def for_pose(_):
            return lambda obs: model.predict(obs, deterministic=True)[0]

        e = evaluate(eval_env, seed, for_pose)
        e.update(training_steps=int(num_timesteps), training_episodes=len(episodes),
                 wall_episodes=sum(1 for x in episodes if x["reason"] == "collision"),
                 wall_time_s=round(time.time() - t0, 3))
        evaluations.append(e)
        if log:
            log("%s seed %d: %6d training steps, %4d episodes (%d on a wall): %5.1f steps, %2d/10 (optimal %.1f)" % (
                algorithm, seed, e["training_steps"], e["training_episodes"], e["wall_episodes"], e["mean_all"],
                e["successes"], optimal["mean_all"]))

    class EvalEvery(BaseCallback):
        def _on_step(self):
            if self.num_timesteps % every == 0:
                evaluate_policy(self.num_timesteps)
            return True

    evaluate_policy(0)
    model.learn(total_timesteps=steps_total, callback=EvalEvery())
    if evaluations[-1]["training_steps"] != model.num_timesteps:
        evaluate_policy(model.num_timesteps)
    return {
        "algorithm": algorithm, "library": "stable-baselines3", "env_id": env_id, "backend": backend,
        "hyperparameters": hyperparameters(model, algorithm), "versions": versions(),
        "train_steps": int(model.num_timesteps), "eval_every_steps": every,
        "optimal": optimal, "evaluations": evaluations, "episodes": episodes,
        "wall_time_s": round(time.time() - t0, 3),
    }


def run(path, seed, variant, out, log=None):
    cfg = load_config(path, variant)
    import gymnasium

    import b21r_learn  # noqa: F401

    probe = gymnasium.make(cfg["reference.env"], backend=cfg["reference.backend"])
    spec = probe.unwrapped.task_spec
    axis, values = vary_axis(cfg["experiment.vary"], path)
    result = {
        "format": FORMAT, "experiment": cfg["experiment.name"], "title": cfg["experiment.title"], "kind": KIND,
        "variant": variant, "variant_index": values.index(variant.split("=", 1)[1]) if variant else 0,
        "seed": seed, "command": " ".join([os.path.basename(sys.executable), "-m", "b21r_exp.reference"] + sys.argv[1:]),
        "task": ENVS[cfg["reference.env"]], "dt_s": 0.1, "step_limit": int(spec["step_limit"]),
        "eval_starts": int(b21r_learn._core.N_EVAL_STARTS),
        "settings": {k: v for k, v in cfg.items()},
        "reference": train(cfg, seed, log),
    }
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        json.dump(result, f, indent=1)
    os.replace(tmp, out)
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(prog="b21r_exp.reference", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--seed", type=int)
    ap.add_argument("--variant", default="")
    ap.add_argument("--out")
    ap.add_argument("--plan", action="store_true", help="print the experiment's plan as JSON")
    ap.add_argument("--verbose", action="store_true", help="progress on stderr")
    args = ap.parse_args(argv)
    try:
        if args.plan:
            print(json.dumps(plan(args.config)))
            return 0
        if args.seed is None or not args.out:
            ap.error("--seed and --out are needed (or --plan)")
        log = (lambda m: print(m, file=sys.stderr, flush=True)) if args.verbose else None
        run(args.config, args.seed, args.variant, args.out, log)
    except ConfigError as e:
        print("b21r_exp.reference: %s" % e, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
