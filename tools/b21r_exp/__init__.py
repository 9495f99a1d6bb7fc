# SPDX-License-Identifier: MIT
"""b21r_exp: the experiment side of the product (tools/b21r_experiments.py is its command).

- sweep:   the (experiment, variant, seed) tasks of the configs in tools/experiments/, run as Ray
           tasks of b21r-experiment, resumable, with progress; one result file per task.
- reference: reference learners (Stable-Baselines3 SAC, PPO, TD3 from scratch on the Gymnasium
           environments), experiments of kind `reference` run by the same sweep.
- results: loading result files and the per-seed numbers every claim is computed from.
- stats:   confidence intervals and the tests (scipy).
- figures: the paper-style figures (matplotlib).
- report:  docs/RESULTS.md, our numbers next to the paper's claims.
"""
