# SPDX-License-Identifier: MIT
"""docs/RESULTS.md: our numbers next to the paper's claims, point by point. Tables and every yes/no
are generated from the result files (each yes/no by the test named beside it); the prose between
`<!-- prose:NAME -->` and `<!-- /prose:NAME -->` is written by people and kept when the report is
generated again."""
import json
import math
import os
import re
import subprocess
import time

from b21r_exp import analysis, figures, reference, results, stats
from b21r_exp.analysis import fmt_ci, fmt_median, fmt_p, fmt_steps

PROSE_RE = re.compile(r"<!-- prose:([a-z0-9_]+) -->\n(.*?)<!-- /prose:\1 -->", re.S)
PROSE_DEFAULT = "_(Prose to be written after the final run: what the numbers mean, and why we differ where we do.)_\n"


def verdict(h):
    return "**yes**" if h is True else ("**no**" if h is False else "undecided")


class Doc:
    def __init__(self, old_prose):
        self.lines = []
        self.old = old_prose

    def add(self, *lines):
        self.lines.extend(lines)

    def prose(self, name):
        self.add("<!-- prose:%s -->" % name, self.old.get(name, PROSE_DEFAULT).rstrip("\n"), "<!-- /prose:%s -->" % name, "")

    def claims(self, cs, header="the paper's claim"):
        self.add("| %s | our measurement | test | holds? |" % header, "|---|---|---|---|")
        for c in cs:
            self.add("| %s | %s | %s | %s |" % (c["paper"], c["measure"], c["test"], verdict(c["holds"])))
        self.add("")

    def figure(self, fig_rel, name, caption):
        self.add("![%s](%s)" % (name, fig_rel), "", "_%s_" % caption, "")


def git_commit(repo):
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True,
                              text=True).stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def seeds_of(rs):
    s = sorted({r["seed"] for r in rs})
    return "%d-%d" % (s[0], s[-1]) if s == list(range(s[0], s[-1] + 1)) else ",".join(map(str, s))


def fmt_paired(d, digits=1):
    """A paired comparison (stats.paired) as "difference ± CI, p (significant)"."""
    return "%s, %s%s" % (fmt_ci(d["mean_diff"], d["ci"], digits), fmt_p(d["p"]),
                         " (significant)" if d["significant"] else "")


def hours_row(name, S):
    m, hw, n = S["training_hours"]
    return "| %s | %d | %s | %s | %s | %s |" % (name, n, fmt_ci(m, hw, 2), fmt_ci(*S["eval_hours"][:2], 2),
                                                fmt_ci(*S["hours_to_switch"][:2], 2), "%.0f s" % S["wall_s"])


def sources_table(doc, S):
    doc.add("Who drove the phase-two training steps (mean fraction over seeds, 95 % CI):", "",
            "| " + " | ".join(results.SOURCES) + " |", "|" + "---|" * len(results.SOURCES))
    doc.add("| " + " | ".join(fmt_ci(100 * v[0], 100 * v[1] if not math.isnan(v[1]) else math.nan, 1) + " %"
                              for v in (S["phase_two_sources"][k] for k in results.SOURCES)) + " |", "")


def curve_table(doc, S):
    doc.add("| training runs | phase two (fraction of seeds) | steps, failures at the limit | steps, successful runs | successes / 10 | store fill |",
            "|---|---|---|---|---|---|")
    for c in S["curve"]:
        doc.add("| %d | %.1f | %s | %s | %s | %s |" % (c["training_runs"], c["phase2_fraction"], fmt_ci(*c["mean_all"][:2]),
                                                   fmt_ci(*c["mean_succ"][:2]), fmt_ci(*c["successes"][:2]),
                                                   fmt_ci(*c["store_fill"][:2], 0)))
    refs = ", ".join("%s %s" % (analysis.ref_label(k), fmt_ci(*v[:2])) for k, v in S["refs"].items())
    doc.add("", "Comparators (mean steps over seeds, failures at the step limit): %s; best example (shortest "
            "phase-one run) %s; mean phase-one run %s." % (refs or "none", fmt_ci(*S["best_example"][:2]),
                                                            fmt_ci(*S["mean_example"][:2])), "")


# Sections that can be regenerated alone (`tools/b21r_experiments.py report --section NAME`): each
# lies between `<!-- section:NAME -->` and `<!-- /section:NAME -->` in the report.
SECTION_RE = re.compile(r"<!-- section:([a-z0-9_]+) -->\n.*?<!-- /section:\1 -->\n+", re.S)
DOORWAY = "doorway"
DOORWAY_HEADING = "Doorway passing (a third task, not in the paper)"
EXPLORE_STUDY = "explore_study"


def doorway_section(doc, data, rel, caps):
    """The doorway task: the learner against the sloppy example policy and the reference controller
    from the same poses, how the runs ended, the learning curve. Returns (S, claims) or (None, [])."""
    doc.add("<!-- section:%s -->" % DOORWAY, "## %s" % DOORWAY_HEADING, "",
            "A room divided by a wall with a door 1 m wide (the B21r is 0.52 m across), the goal 1.5 m beyond "
            "it; the state is the door's frame as the laser finds it (wall distance, offset from the door's "
            "centre line, heading, distance to the nearer jamb: `features/doorway.h`); reward +1 at the goal, -1 "
            "on a collision, both ending the run; gamma 0.95; 0.4 m/s. Phase one is driven by a sloppy "
            "proportional example (it heads for a point 1.5 m before the door, then for the goal; gain drawn per "
            "run in 1-2); the reference controller (a searched line-following law) evaluates only. Same protocol "
            "as Figs. 4 and 9-10. The task is a declaration (`lib/tasks/src/task_doorway.c`); no learner, loop or "
            "trainer code changed to add it.", "")
    if DOORWAY not in data:
        doc.add("_Not run yet: `tools/b21r_experiments.py run report %s --section %s`._" % (DOORWAY, DOORWAY), "")
        doc.prose(DOORWAY)
        doc.add("<!-- /section:%s -->" % DOORWAY, "")
        return None, []
    rs = next(iter(data[DOORWAY].values()))
    S = analysis.learn_summary(rs)
    doc.add("Made by: `tools/b21r_experiments.py run report %s --section %s` (seeds %s; file "
            "`tools/experiments/%s.conf`; without `--section` the whole report is regenerated)." % (
                DOORWAY, DOORWAY, seeds_of(rs), DOORWAY), "")
    fig = DOORWAY + ".png"
    doc.figure(os.path.join(rel, fig), DOORWAY, caps.get(fig, ""))
    cs = analysis.doorway_claims(S)
    doc.claims(cs, header="the claim (the issue's; not in the paper)")
    seeds = S["seeds"]
    n_poses = len(seeds[0]["final_steps"] or []) if seeds else 0
    doc.add("The final block and the comparators from the same %d poses (mean over seeds, 95 %% CI; a failure "
            "is a collision or the step limit of %d):" % (n_poses, S["step_limit"]), "",
            "| policy | steps, failures at the limit | steps, successful runs | successes / %d |" % n_poses,
            "|---|---|---|---|")

    def row(label, blocks):
        blocks = [b for b in blocks if b is not None]
        doc.add("| %s | %s | %s | %s |" % (label, fmt_ci(*stats.mean_ci([b["mean_all"] for b in blocks])[:2]),
                                           fmt_ci(*stats.mean_ci([b["mean_succ"] for b in blocks])[:2]),
                                           fmt_ci(*stats.mean_ci([b["successes"] for b in blocks])[:2])))

    row("learned policy, final block", [x["final"] for x in seeds])
    row("learned policy, last phase-one block", [x["last_phase_one"] for x in seeds])
    for k in sorted(S["refs"], key=lambda k: (k != "optimal", k)):
        row(analysis.ref_label(k) + ("" if k != "optimal" else " (reference)"), [x["refs"].get(k) for x in seeds])
    doc.add("")
    # Where the failures are: per evaluation pose, the seeds whose run from it failed.
    try:  # the poses as the task declares them (the result files hold their count only)
        from b21r_task_world import WorldUnavailable, declared_world
        starts = declared_world(DOORWAY)["starts"]
    except (ImportError, WorldUnavailable):
        starts = []
    names = sorted(S["refs"], key=lambda k: (k != "example", k != "optimal", k))

    def fails(blocks, i):
        return sum(1 for b in blocks if b is not None and i < len(b) and not b[i])

    final_ok = [r["learning"]["blocks"][-1]["success"] if r["learning"]["blocks"] else None for r in rs]
    p1_ok = [([b for b in r["learning"]["blocks"] if b["phase"] == 1] or [None])[-1] for r in rs]
    p1_ok = [b["success"] if b is not None else None for b in p1_ok]
    doc.add("Failures by evaluation pose (seeds, of %d, whose run from the pose failed):" % len(rs), "",
            "| pose | learned, final block | learned, last phase-one block | %s |" % " | ".join(
                analysis.ref_label(k) for k in names), "|---|---|---|" + "---|" * len(names))
    for i in range(n_poses):
        label = "%d" % i if i >= len(starts) else "%d (%.1f, %.1f, %.1f)" % (i, *starts[i])
        doc.add("| %s | %d | %d | %s |" % (label, fails(final_ok, i), fails(p1_ok, i), " | ".join(
            "%d" % fails([r["references"][k]["success"] if k in r["references"] else None for r in rs], i)
            for k in names)))
    doc.add("")
    oc = analysis.outcome_counts(rs)

    def ends(c):
        return ", ".join("%s %d" % (k.replace("_", " "), c.get(k, 0)) for k in ("goal", "collision", "step_limit")
                         if c.get(k, 0) or k != "step_limit") or "none"

    doc.add("How the runs ended, all seeds together: phase-one training runs (the example policy) %s; phase-two "
            "training runs %s; the learner's evaluation runs %s, of which the final block's %s. (The comparators' "
            "failures are in the table above; the runner records them as failures without their cause.)" % (
                ends(oc["train_1"]), ends(oc["train_2"]), ends(oc["eval_all"]), ends(oc["eval_final"])), "")
    curve_table(doc, S)
    sources_table(doc, S)
    doc.prose(DOORWAY)
    doc.add("<!-- /section:%s -->" % DOORWAY, "")
    return S, cs


REFERENCE_SECTION = "reference_learners"


def reference_configs(configs_dir):
    """Names of the reference experiments (experiment.kind = reference) in configs_dir."""
    return [n[:-5] for n in sorted(os.listdir(configs_dir))
            if n.endswith(".conf") and reference.is_reference(os.path.join(configs_dir, n))]


def reference_section(doc, data, configs_dir, rel, caps):
    """The reference learners against the product's learner, by training steps: one table and one
    figure per reference experiment, from whichever result files exist."""
    doc.add("<!-- section:%s -->" % REFERENCE_SECTION, "## Reference learners: standard learners from scratch, by training steps", "",
            "What a user would pick instead of the product's learner: Stable-Baselines3 learners with their default "
            "hyperparameters and no examples, trained on the product's Gymnasium environment and evaluated as the "
            "product's evaluation blocks are (the deterministic policy from the task's 10 evaluation poses, a run "
            "that does not reach the goal counted at the step limit), every 1,000 training steps and before "
            "training. Steps are environment steps of training: for the product's learner those of both phases, its "
            "examples included; evaluation runs are not counted for either. \"Within 1 % and staying\": the training "
            "steps at the first evaluation from which every later one is within 1 % (3 %) of the optimal "
            "controller's mean from the same poses; a seed whose final evaluation is not is censored (counted as "
            "more than its budget; the column says how many). Medians over seeds with their distribution-free 95 % "
            "interval in brackets (order statistics: for 10 seeds the 2nd and 9th of 10). Episodes ending on a wall: "
            "training episodes that ended in a collision.", "")
    names = reference_configs(configs_dir)
    product, missing = analysis.product_rows(data)
    for name in names:
        doc.add("### %s" % name, "")
        if name not in data:
            doc.add("_Not run yet: `tools/b21r_experiments.py run %s`._" % name, "")
            continue
        variants = data[name]
        rs = next(iter(variants.values()))
        doc.add("Made by: `tools/b21r_experiments.py run %s` (seeds %s; file `tools/experiments/%s.conf`)." % (
            name, seeds_of(rs), name), "")
        fig = name + ".png"
        doc.figure(os.path.join(rel, fig), name, caps.get(fig, ""))
        rows = analysis.reference_rows(variants)
        corridor = rs[0]["task"] == "corridor"
        hp = {}
        for r in variants.values():
            R = r[0]["reference"]
            hp[R["algorithm"]] = R["hyperparameters"]
        if corridor:
            rows = rows + product
        opt = rows[0]["optimal"]
        doc.add("Optimal controller from the same poses: %s steps." % fmt_ci(*opt[:2]), "",
                "| learner | back-end | seeds | training steps (budget) | training steps to within 1 % and staying "
                "(censored) | to within 3 % and staying (censored) | training episodes ending on a wall, in all "
                "(seeds with any) | ... until within 1 % and staying | final evaluation: steps | final: 10/10 poses |",
                "|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            doc.add("| %s | %s | %d | %s | %s (%d) | %s (%d) | %s (%d) | %s | %s | %d of %d seeds |" % (
                r["label"], ", ".join(r["backend"]), r["n"], fmt_steps(r["budget"][0]),
                fmt_median(r["to_0.01"]), r["censored_0.01"], fmt_median(r["to_0.03"]), r["censored_0.03"],
                fmt_median(r["walls"]), r["walls_any"], fmt_median(r["walls_until_0.01"]),
                fmt_median(r["final"], 1), r["final_all10"], r["n"]))
        if corridor:
            for exp, var, label in missing:
                doc.add("| %s | | | _not run yet: `tools/b21r_experiments.py run %s`%s_ | | | | | | |" % (
                    label, exp, " (variant `%s`)" % var if var else ""))
        doc.add("")
        if corridor:
            doc.add("The product's rows come from the result files of %s, whichever exist (the emulated B21r, "
                    "evaluation blocks every 5 training runs, the training steps of both phases, examples "
                    "included)." % ", ".join("`%s`%s" % (e, " (`%s`)" % v if v else "") for e, v, _ in
                                             analysis.PRODUCT_PROGRESS), "")
        doc.add("Hyperparameters (Stable-Baselines3's defaults, read back from the models): %s." % "; ".join(
            "%s: %s" % (a.upper(), ", ".join("%s %s" % (k, v) for k, v in h.items())) for a, h in hp.items()), "")
    doc.prose("reference_learners")
    doc.add("<!-- /section:%s -->" % REFERENCE_SECTION, "")


# The sections that can be regenerated alone: the experiments whose figures they show, and the
# heading a whole report has after them (where a report without the section gets it; with several,
# the first the report has).
SECTIONS = {
    DOORWAY: {"figures": lambda configs_dir: (DOORWAY,), "before": "\n## Learning without examples"},
    REFERENCE_SECTION: {"figures": lambda configs_dir: tuple(reference_configs(configs_dir)),
                        "before": "\n## Ablations\n"},
    EXPLORE_STUDY: {"figures": lambda configs_dir: tuple(sorted(
        n[:-5] for n in os.listdir(configs_dir) if n.startswith(analysis.EXPLORE_PREFIX) and n.endswith(".conf"))),
                    "before": ("\n<!-- section:%s -->" % REFERENCE_SECTION, "\n## Ablations\n")},
}


def write_section(out, fig_dir, path, configs_dir, section=DOORWAY):
    """Regenerates one marked section of an existing report (and its figures) from the result
    files, keeping every other line: for when the other experiments' results are not at hand. A
    report without the section gets it where a whole report has it (before the section that
    follows it there), else at the end."""
    if section not in SECTIONS:
        raise ValueError("sections that can be regenerated alone: %s" % ", ".join(sorted(SECTIONS)))
    data = results.load(out, configs_dir)
    with open(path) as f:
        text = f.read()
    old = {m.group(1): m.group(2) for m in PROSE_RE.finditer(text)}
    doc = Doc(old)
    caps = {}
    figures.make_all(out, fig_dir, configs_dir, caps, only=SECTIONS[section]["figures"](configs_dir))
    rel = os.path.relpath(fig_dir, os.path.dirname(os.path.abspath(path)))
    if section == DOORWAY:
        doorway_section(doc, data, rel, caps)
    elif section == EXPLORE_STUDY:
        explore_study_section(doc, data, rel, caps)
    else:
        reference_section(doc, data, configs_dir, rel, caps)
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    doc.lines.insert(3, "_This section was generated on its own (`tools/b21r_experiments.py report --section %s`) from "
                        "the result files in `%s` on %s, source commit `%s`._" % (
                            section, os.path.relpath(out, repo) if os.path.isabs(out) else out,
                            time.strftime("%Y-%m-%d"), git_commit(repo)))
    doc.lines.insert(4, "")
    new = "\n".join(doc.lines) + "\n"
    m = [x for x in SECTION_RE.finditer(text) if x.group(1) == section]
    if m:
        text = text[: m[0].start()] + new + text[m[0].end():]
    else:
        before = SECTIONS[section]["before"]  # a heading, or headings to try in turn
        at = next((text.find(b) for b in ((before,) if isinstance(before, str) else before) if b in text), -1)
        text = text[: at + 1] + new + text[at + 1:] if at >= 0 else text.rstrip("\n") + "\n\n" + new
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)
    return path


def _reached(r):
    p = r["pooled"]
    return "%d/%d = %.0f %% (%.0f-%.0f %%)" % (p["k"], p["n"], 100 * p["fraction"], 100 * p["lo"], 100 * p["hi"])


def _median(r):
    return "> %.0f" % r["limit_h"] if math.isinf(r["median_h"]) else "%.3g" % r["median_h"]


def _ratio(r, paper_h):
    m, hw, _ = r["hours"]
    if math.isnan(m) or not paper_h:
        return "n/a"
    return "%.2g" % (m / paper_h) if math.isnan(hw) else "%.2g (%.2g-%.2g)" % (m / paper_h, max(m - hw, 0) / paper_h,
                                                                        (m + hw) / paper_h)


def _rows_table(doc, groups, paper_of):
    """One row per variant. paper_of(row) gives the paper's (share %, hours) to compare with, or
    None; with a share, the runs that reached the reward are tested against it."""
    shares = any(paper_of(r) and paper_of(r)[0] is not None for _, g in groups for r in g["rows"])
    doc.add("| experiment | variant | reached | %stime [h] | median [h] | fastest [h] | attempts | × paper |" % (
        "test against the paper's share | " if shares else ""), "|---|---|---|%s---|---|---|---|---|" % (
        "---|" if shares else ""))
    for n, g in groups:
        for i, r in enumerate(g["rows"]):
            paper = paper_of(r)
            test = ""
            if shares:
                if paper and paper[0] is not None:
                    t = stats.binomial(r["successes"], r["runs"], paper[0] / 100.0, "two-sided")
                    test = "%.1f %%: %s | " % (paper[0], fmt_p(t["p"]))
                else:
                    test = "n/a | "
            doc.add("| %s | %s | %s | %s%s | %s | %.3g | %s | %s |" % (
                "`%s`" % n if i == 0 else "", r["variant"].replace("experiment.explore_", "") or "-", _reached(r),
                test, fmt_ci(*r["hours"][:2], 3), _median(r), r["min_h"], fmt_ci(*r["attempts"][:2], 1),
                _ratio(r, paper[1] if paper else None)))
    doc.add("")


def explore_study_section(doc, data, rel, caps):
    """The sensitivity study of learning without examples (experiments explore_*): which modelling
    assumptions move the time to the first reward and the success fractions toward the paper's.
    Per task (the experiment's kind): the one-at-a-time experiments, then the sweeps of the
    paper's own axis under combinations (with the paper's own file first when it was run)."""
    study = analysis.explore_study(data)
    doc.add("<!-- section:%s -->" % EXPLORE_STUDY, "## Learning without examples: which assumptions (sensitivity study)", "")
    if not study:
        doc.add("_Not run yet: `tools/b21r_experiments.py run report 'explore_*' --section %s`._" % EXPLORE_STUDY, "")
        doc.prose("explore_study")
        doc.add("<!-- /section:%s -->" % EXPLORE_STUDY, "")
        return
    names = sorted(study)
    seeds = sorted({s for g in study.values() for r in g["rows"] for s in r["seeds"]})
    cpu = sum(r["wall_s"] for g in study.values() for r in g["rows"])
    doc.add("Made by: `tools/b21r_experiments.py run 'explore_*'` (%d experiment files `tools/experiments/explore_*.conf`, "
            "seeds %d-%d each, %.0f runner seconds; each file's header says what it fixes and varies; "
            "[`docs/experiments.md`](experiments.md) lists the keys)." % (len(names) + ("explore_product_learner" in data),
                                                                          seeds[0], seeds[-1], cpu), "",
            "Each row changes the paper's study as Fig. 6 and Table I read it (the first row of each group, "
            "unless the group says otherwise) in one assumption. _reached_: runs that found the reward within the "
            "time limit (one simulated week unless stated), pooled over seeds with the Clopper-Pearson 95 % "
            "interval. _time_: time to the first reward of the runs that found it (robot time: driving plus "
            "the cost of restarts), mean over the seeds of each seed's mean with the 95 % t interval. _median_: "
            "over all runs, a run that never found it counting as never ('> limit' when half or more did "
            "not). _attempts_: attempts per run (a collision or the attempt's step limit ends one). _× paper_: "
            "time over the paper's (Fig. 6: the fastest, 2 h; Table I: its time at the same distance), with the "
            "interval's ends.", "")
    kinds = sorted({g["kind"] for g in study.values()},
                   key=lambda k: (list(analysis.EXPLORE_KINDS).index(k) if k in analysis.EXPLORE_KINDS else 99, k))
    for kind in kinds:
        info = analysis.EXPLORE_KINDS.get(kind, {"task": kind, "single": "", "sweep": "", "paper_file": None,
                                                 "paper_of_single": lambda r: None, "paper_of_sweep": lambda r: None})
        single = analysis.study_groups(study, kind, False)
        sweeps = analysis.study_groups(study, kind, True)
        paper_file = info.get("paper_file")
        if paper_file in data:
            sweeps = [(paper_file, {"title": "the paper's study as we read it", "kind": kind, "axis": info["paper_axis"],
                                    "rows": [analysis.explore_variant(v, rs) for v, rs in data[paper_file].items()]})
                      ] + sweeps
        if single:
            doc.add("### %s, one assumption at a time%s" % (info["task"], info["single"]), "")
            fig = "%s_sensitivity.png" % kind
            doc.figure(os.path.join(rel, fig), fig[:-4], caps.get(fig, ""))
            _rows_table(doc, single, info["paper_of_single"])
        if sweeps:
            doc.add("### %s under combinations of assumptions%s" % (info["task"], info["sweep"]), "")
            fig = "%s_combinations.png" % kind
            doc.figure(os.path.join(rel, fig), fig[:-4], caps.get(fig, ""))
            for n, g in sweeps:
                doc.add("- `%s`: %s." % (n, g["title"]))
            doc.add("")
            _rows_table(doc, sweeps, info["paper_of_sweep"])
            if kind == "explore_corridor":
                doc.claims([analysis.fastest_claim(n, g["rows"]) for n, g in sweeps])
    product_section(doc, study, data, rel, caps)
    doc.prose("explore_study")
    doc.add("<!-- /section:%s -->" % EXPLORE_STUDY, "")


def product_section(doc, study, data, rel, caps):
    """What phase one saves a user of this product: random exploration under the product's own
    assumptions against the Fig. 4 session's training, and the product's learner without examples."""
    prod = study.get("explore_corridor_product")
    learner = data.get("explore_product_learner")
    if prod is None and learner is None:
        return
    doc.add("### What phase one saves a user of this product", "")
    train = []
    if "fig4_corridor_examples" in data:
        fig4 = next(iter(data["fig4_corridor_examples"].values()))
        train = [(results.learn_seed(r)["training_hours"], results.learn_seed(r)["phase_one_runs"] +
                  results.learn_seed(r)["phase_two_runs"]) for r in fig4]
    if prod is not None:
        doc.add("Random exploration under the product's assumptions (`explore_corridor_product`: %s) against the Fig. 4 "
                "session's training on the same terms (its training driving plus, per training run, the same "
                "restart cost: on the robot an operator puts it back after every run). _saving_: random "
                "exploration's time to the first reward minus the session's training (Welch 95 %% interval over "
                "seeds); positive: the examples finish training before random exploration finds its first "
                "reward." % (
                    prod["title"]), "",
                "| restart cost | reached | random exploration: first reward [h] | attempts | Fig. 4 session: "
                "training [h] | saving [h] |", "|---|---|---|---|---|---|")
        for r in prod["rows"]:
            restart_h = float(r["settings"].get("restart_s", 0.0)) / 3600.0
            if train:
                sess = [h + n * restart_h for h, n in train]
                w = stats.welch(r["seed_means"], sess, "two-sided")
                sess_txt = fmt_ci(*stats.mean_ci(sess)[:2], 3)
                save = "%s (%s)" % (fmt_ci(w["mean_diff"], w["ci"], 3), fmt_p(w["p"]))
            else:
                sess_txt = save = "Fig. 4 not run (`tools/b21r_experiments.py run fig4_corridor_examples`)"
            doc.add("| %.0f s | %s | %s | %s | %s | %s |" % (restart_h * 3600.0, _reached(r), fmt_ci(*r["hours_all"][:2], 3),
                                                        fmt_ci(*r["attempts"][:2], 0), sess_txt, save))
        doc.add("")
    if learner is not None:
        rows = analysis.learner_without_examples(learner)
        fig4_final = {}
        if "fig4_corridor_examples" in data:
            fig4_final = {s["seed"]: s["final"]["mean_all"] for s in
                          (results.learn_seed(r) for r in next(iter(data["fig4_corridor_examples"].values())))}
        doc.figure(os.path.join(rel, "explore_product_learner.png"), "explore_product_learner",
                   caps.get("explore_product_learner.png", ""))
        doc.add("The product's learner without examples (`explore_product_learner`: no phase one, no advisor, %s "
                "training runs; evaluation blocks of 10 fixed poses every 5 runs, failures at the step limit %d):" % (
                    " or ".join(str(r["runs"]) for r in rows), rows[0]["step_limit"]), "",
                "| variant | sessions with a training run at the goal | first such run | driving until then [h] | "
                "blocks with all 10 poses reached | final block: steps | final successes / 10 | training [h] | final "
                "minus Fig. 4's (paired by seed) |", "|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            common = sorted(set(r["final_by_seed"]) & set(fig4_final))
            if common:
                d = stats.paired([r["final_by_seed"][s] for s in common], [fig4_final[s] for s in common], "two-sided")
                diff = fmt_paired(d)
            else:
                diff = "Fig. 4 not run"
            doc.add("| %s | %d of %d | %s | %s | %s of %d | %s | %s | %s | %s |" % (
                r["variant"] or "default", r["reached"], r["n"], fmt_ci(*r["first_run"][:2]),
                fmt_ci(*r["first_hours"][:2], 3),
                fmt_ci(*r["all10_blocks"][:2]), r["runs"] // 5, fmt_ci(*r["final_all"][:2]),
                fmt_ci(*r["final_succ"][:2]), fmt_ci(*r["training_hours"][:2], 2), diff))
        doc.add("")


def write(out, fig_dir, path, configs_dir):
    data = results.load(out, configs_dir)
    old = {}
    if os.path.exists(path):
        with open(path) as f:
            old = {m.group(1): m.group(2) for m in PROSE_RE.finditer(f.read())}
    doc = Doc(old)
    caps = {}
    figures.make_all(out, fig_dir, configs_dir, caps)
    rel = os.path.relpath(fig_dir, os.path.dirname(os.path.abspath(path)))
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    doc.add("# Results: the paper's experiments in the emulated B21r", "",
            "Generated by `tools/b21r_experiments.py` (command `report`) from the result files in `%s` on %s, "
            "source commit `%s`. Do not edit the tables: run `tools/b21r_experiments.py` again. Text between "
            "`prose` markers is kept." % (os.path.relpath(out, repo), time.strftime("%Y-%m-%d"), git_commit(repo)), "",
            "How to read it: every number is a mean over seeds with its 95 % Student-t interval across seeds. "
            "An evaluation run that does not reach the goal counts at the run's step limit (\"failures at the "
            "limit\"), shown beside the mean of the successful runs. Comparisons of two policies use the same "
            "seeds, the same emulator noise and the same 10 evaluation poses and are paired by seed. Each claim "
            "is decided by the test named beside it at the 5 % level; \"undecided\" means too few seeds.", "")
    doc.prose("summary")
    summary_claims = []
    hours = []

    def section_cmd(name, rs):
        doc.add("Made by: `tools/b21r_experiments.py run %s` (seeds %s; file `tools/experiments/%s.conf`)." % (
            name, seeds_of(rs), name), "")

    for name, heading, human in (("fig4_corridor_examples", "Corridor following with code examples (Fig. 4)", False),
                                 ("fig5_corridor_human", "Corridor following with a sloppy human driver (Fig. 5)", True)):
        doc.add("## %s" % heading, "")
        if name not in data:
            doc.add("_Not run yet: `tools/b21r_experiments.py run %s`._" % name, "")
            continue
        rs = next(iter(data[name].values()))
        S = analysis.learn_summary(rs)
        section_cmd(name, rs)
        fig = figures.LEARN_FIGS[name]
        doc.figure(os.path.join(rel, fig), name, caps.get(fig, ""))
        cs = analysis.corridor_claims(S, human) + [analysis.hours_claim(S)]
        doc.claims(cs)
        summary_claims += [(heading, c) for c in cs]
        curve_table(doc, S)
        sources_table(doc, S)
        hours.append(hours_row(name, S))
        doc.prose(name)

    doc.add("## Obstacle avoidance (Figs. 7-10)", "")
    if "fig9_10_obstacles" in data:
        rs = next(iter(data["fig9_10_obstacles"].values()))
        S = analysis.learn_summary(rs)
        section_cmd("fig9_10_obstacles", rs)
        for fig in ("fig9_obstacles_successes.png", "fig10_obstacles_steps.png"):
            doc.figure(os.path.join(rel, fig), fig[:-4], caps.get(fig, ""))
        cs = analysis.obstacle_claims(S) + [analysis.hours_claim(S)]
        doc.claims(cs)
        summary_claims += [("Obstacle avoidance", c) for c in cs]
        curve_table(doc, S)
        sources_table(doc, S)
        hours.append(hours_row("fig9_10_obstacles", S))
    else:
        doc.add("_Not run yet: `tools/b21r_experiments.py run fig9_10_obstacles`._", "")
    doc.prose("obstacles")

    S, cs = doorway_section(doc, data, rel, caps)
    if S is not None:
        summary_claims += [("Doorway passing", c) for c in cs]
        hours.append(hours_row(DOORWAY, S))

    doc.add("## Learning without examples: the corridor (Fig. 6)", "")
    if "fig6_explore_corridor" in data:
        rows = analysis.explore_corridor_summary(data["fig6_explore_corridor"])
        section_cmd("fig6_explore_corridor", next(iter(data["fig6_explore_corridor"].values())))
        doc.figure(os.path.join(rel, "fig6_explore_corridor.png"), "fig6", caps.get("fig6_explore_corridor.png", ""))
        doc.add("| rotation limit [rad/s] | runs | reached within %.0f h | time to the first reward [h], mean over seeds | fastest [h] | median [h] |" % rows[0]["limit_h"],
                "|---|---|---|---|---|---|")
        for r in rows:
            doc.add("| %g | %d | %d | %s | %.3g | %.3g |" % (r["limit"], r["runs"], r["successes"], fmt_ci(*r["hours"][:2], 3),
                                                          r["min_h"], r["median_h"]))
        doc.add("")
        fastest = min((r["hours"][0] for r in rows), default=math.nan)
        c1 = analysis.claim("The fastest setting needs slightly over two hours to the first reward.",
                            "fastest mean over the limits: %.3f h" % fastest,
                            "compare the mean with 2 h (more than 2 h?)", None if math.isnan(fastest) else fastest > 2.0,
                            rows[0]["n_seeds"])
        cs = [c1]
        if "fig4_corridor_examples" in data:
            train = [results.learn_seed(r)["training_hours"] for r in next(iter(data["fig4_corridor_examples"].values()))]
            best = min(rows, key=lambda r: r["hours"][0])
            w = stats.welch([t for t in best["times_h"]], train, "greater")
            cs.append(analysis.claim(
                "Phase-one training saves a great deal of time: the first reward alone takes longer than the whole "
                "two-phase training.",
                "random exploration (limit %g rad/s) %.3f h to the first reward vs %s h of training with examples "
                "(Fig. 4)" % (best["limit"], best["hours"][0], fmt_ci(*stats.mean_ci(train)[:2], 2)),
                "%s, %s" % (w["test"], fmt_p(w["p"])), w["significant"] if not math.isnan(w["p"]) else None,
                rows[0]["n_seeds"]))
        doc.claims(cs)
        summary_claims += [("Fig. 6", c) for c in cs]
    else:
        doc.add("_Not run yet: `tools/b21r_experiments.py run fig6_explore_corridor`._", "")
    doc.prose("fig6")

    doc.add("## Learning without examples: the goal task (Table I)", "")
    if "table1_explore_goal" in data:
        rows = analysis.explore_goal_summary(data["table1_explore_goal"])
        section_cmd("table1_explore_goal", next(iter(data["table1_explore_goal"].values())))
        doc.add("| start distance | paper: successful | ours: successful (mean over seeds) | ours: pooled (95 % CI) | "
                "test against the paper's fraction | paper: time [h] | ours: time of the successful runs [h] |",
                "|---|---|---|---|---|---|---|")
        cs = []
        for r in rows:
            p = r["pooled"]
            paper = r["paper"] or (math.nan, math.nan)
            doc.add("| %g m | %.1f %% | %s %% | %d/%d = %.1f %% (%.1f-%.1f %%) | %s, %s | %.2f | %s |" % (
                r["distance"], paper[0], fmt_ci(100 * r["fraction"][0], 100 * r["fraction"][1] if not math.isnan(r["fraction"][1]) else math.nan),
                p["k"], p["n"], 100 * p["fraction"], 100 * p["lo"], 100 * p["hi"], p["test"], fmt_p(p["p"]),
                paper[1], fmt_ci(*r["hours"][:2], 4)))
            cs.append(analysis.claim("From %g m, %.1f %% of the runs reach the goal within a week." % (r["distance"], paper[0]),
                                     "%.1f %% (%d/%d)" % (100 * p["fraction"], p["k"], p["n"]),
                                     "%s, %s (holds = not significantly different)" % (p["test"], fmt_p(p["p"])),
                                     None if p["n"] == 0 else not p["significant"], r["n_seeds"]))
        doc.add("")
        three = next((r for r in rows if r["distance"] == 3.0), None)
        if three is not None:
            t = stats.binomial(three["pooled"]["k"], three["pooled"]["n"], 0.2, "less")
            cs.append(analysis.claim("From 3 m (where the real robot starts) less than one run in five reaches the goal.",
                                     "%.1f %% (%d/%d)" % (100 * t["fraction"], t["k"], t["n"]),
                                     "%s, %s" % (t["test"], fmt_p(t["p"])), t["significant"], three["n_seeds"]))
            h = three["hours"]
            cs.append(analysis.claim("Even those take about six and a half hours, longer than a battery lasts.",
                                     "%s h" % fmt_ci(*h[:2], 4), "mean with 95 % CI above 6 h?",
                                     None if math.isnan(h[0]) or math.isnan(h[1]) else h[0] - h[1] > 6.0, h[2]))
        doc.claims(cs)
        summary_claims += [("Table I", c) for c in cs]
    else:
        doc.add("_Not run yet: `tools/b21r_experiments.py run table1_explore_goal`._", "")
    doc.prose("table1")

    explore_study_section(doc, data, rel, caps)

    reference_section(doc, data, configs_dir, rel, caps)

    doc.add("## Ablations", "")
    for name in sorted(n for n in os.listdir(configs_dir) if n.startswith("ablation_") and n.endswith(".conf")):
        name = name[:-5]
        doc.add("### %s" % name, "")
        if name not in data:
            reason = "not run yet: `tools/b21r_experiments.py run %s`" % name
            with open(os.path.join(configs_dir, name + ".conf")) as f:
                if "experiment.requires" in f.read():
                    reason = ("not run: it needs learner variants of the controller (key `learner`) that this build "
                              "does not have; the sweep runs it once they exist")
            doc.add("_%s%s._" % (reason[0].upper(), reason[1:]), "")
            continue
        variants = data[name]
        summ, comps = analysis.ablation_comparisons(variants)
        rs = next(iter(variants.values()))
        section_cmd(name, rs)
        fig = name + ".png"
        doc.figure(os.path.join(rel, fig), name, caps.get(fig, ""))
        doc.add("| variant | final block: steps (failures at the limit) | final successes / 10 | training driving [h] | phase switch after runs | phase-one data identical to the baseline's (digest) |",
                "|---|---|---|---|---|---|")
        same = {c["variant"]: c["same_data"] for c in comps}
        for v, S in summ.items():
            fin = stats.mean_ci([s["final"]["mean_all"] for s in S["seeds"]])
            suc = stats.mean_ci([s["final"]["successes"] for s in S["seeds"]])
            doc.add("| %s | %s | %s | %s | %s | %s |" % (v, fmt_ci(*fin[:2]), fmt_ci(*suc[:2]), fmt_ci(*S["training_hours"][:2], 2),
                                                       fmt_ci(*S["switch_after"][:2]), "baseline" if v not in same else ("yes" if same[v] else "no")))
        doc.add("", "Each variant against its own references from the same poses (final block, paired by seed; "
                "the example policy at its nominal gain, the middle of the gains its runs drew):", "",
                "| variant | final block, successful runs | example policy, same poses | learned minus example "
                "(final block, failures at the limit) | learned minus optimal (the same) |", "|---|---|---|---|---|")
        for v, S in summ.items():
            R = analysis.against_references(S)
            missing = "not evaluated"
            doc.add("| %s | %s | %s | %s | %s |" % (
                v, fmt_ci(*R["final_succ"][:2]), fmt_ci(*R["example"]["mean"][:2]) if "example" in R else missing,
                fmt_paired(R["example"]["diff"]) if "example" in R else missing,
                fmt_paired(R["optimal"]["diff"]) if "optimal" in R else missing))
        doc.add("", "Phase-one data are identical across variants unless the variant changes phase one itself (the "
                "automatic phase switch ends it at another run; other teachers drive other examples): for a seed the "
                "example policy's gains and start "
                "poses are the same, each run's sensor noise starts from its run id, each run integrates its own "
                "odometry, and the emulator places the robot only once the learner is done, so the learner-driven "
                "evaluation runs in between leave nothing behind (`experiments.learner_variants` checks it).", "",
                "| comparison (paired by seed) | final steps: difference, test | training hours: difference, test |", "|---|---|---|")
        for c in comps:
            f, h = c["final"], c["hours"]
            doc.add("| %s vs %s | %s | %s |" % (c["variant"], c["baseline"], fmt_paired(f), fmt_paired(h, 3)))
        doc.add("")
        hours.append(hours_row(name + " (" + next(iter(variants)) + ")", summ[next(iter(variants))]))
    doc.prose("ablations")

    doc.add("## Simulated robot time", "",
            "The paper: \"all of the training was accomplished in approximately two hours\" (each real-robot "
            "experiment). Ours, per experiment (driving time = steps x 0.1 s; evaluation runs apart):", "",
            "| experiment | seeds | training driving [h] | evaluation driving [h] | driving until the phase switch [h] | runner wall time, all seeds |",
            "|---|---|---|---|---|---|")
    doc.add(*hours)
    doc.add("")

    doc.add("## Runtime of the sweeps", "")
    sweeps_path = os.path.join(out, "sweeps.jsonl")
    if os.path.exists(sweeps_path):
        doc.add("| when | experiments | tasks | failed | wall time | task-seconds | CPUs |", "|---|---|---|---|---|---|---|")
        with open(sweeps_path) as f:
            for line in f.readlines()[-12:]:
                s = json.loads(line)
                doc.add("| %s | %s | %d | %d | %.0f s | %.0f s | %d (%s) |" % (s["when"], ", ".join(s["experiments"]),
                                                                        s["tasks"], s["failed"], s["wall_s"],
                                                                        s["task_seconds"], s["cpus"], s["address"]))
        doc.add("")

    doc.add("## All claims at a glance", "", "| experiment | the paper's claim | holds? | test |", "|---|---|---|---|")
    for exp, c in summary_claims:
        doc.add("| %s | %s | %s | %s |" % (exp, c["paper"], verdict(c["holds"]), c["test"]))
    doc.add("")
    text = "\n".join(doc.lines)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)
    return path
