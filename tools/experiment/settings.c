// SPDX-License-Identifier: MIT
// Experiment keys (one table: parser, errors and reference text cannot drift apart), the
// experiment file loader on top of the controller's parser, result-file helpers, JSON writer.
#define _POSIX_C_SOURCE 200809L
#include "experiment.h"
#include "fw/errfmt.h"

#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef enum xkind { X_STRING, X_CHOICE, X_INT, X_DOUBLE, X_BOOL, X_REFS, X_VARY, X_REQUIRES } xkind_t;

typedef struct xkey {
  const char* name;
  xkind_t kind;
  size_t offset;
  double min;
  double max;
  const char* def;
  const char* doc;
  const char* const* choices;  ///< X_CHOICE: the values, NULL-terminated; the field holds the index
} xkey_t;

static const char* const k_kind_names[] = {"learn", "explore_corridor", "explore_goal", NULL};
static const char* const k_model_names[] = {"kinematic", "ode", NULL};
static const char* const k_random_names[] = {"rotation", "translation", "both", NULL};
static const char* const k_rotation_names[] = {"auto", "uniform", "normal", NULL};
static const char* const k_translation_names[] = {"normal", "uniform", NULL};
static const char* const k_collision_names[] = {"restart", "stay", NULL};
static const char* const k_start_names[] = {"paper", "any_heading", "training", NULL};

#define XOFF(f) offsetof(exp_settings_t, f)

// clang-format off
static const xkey_t k_xkeys[] = {
  {"experiment.name", X_STRING, XOFF(name), 0, 0, "",
   "identifier of the experiment (result folder); \"\" = the file's name without .conf", NULL},
  {"experiment.title", X_STRING, XOFF(title), 0, 0, "",
   "one line describing the experiment, for figures and the report", NULL},
  {"experiment.kind", X_CHOICE, XOFF(kind), 0, 0, "learn",
   "learn: the controller's two-phase schedule in the ODE emulator (in-process); explore_corridor: "
   "random rotation until the first reward in the corridor (paper Fig. 6); explore_goal: the "
   "obstacle-free goal task with Gaussian rotation (paper Table I); both on the kinematic model unless "
   "experiment.explore_model says otherwise", k_kind_names},
  {"experiment.seeds", X_INT, XOFF(seeds), 1, 1000, "10",
   "seeds of a sweep (every reported result: at least 10)", NULL},
  {"experiment.first_seed", X_INT, XOFF(first_seed), 1, 1000000, "1",
   "first seed; the sweep runs first_seed .. first_seed + seeds - 1", NULL},
  {"experiment.world", X_STRING, XOFF(world), 0, 0, "",
   "emulator world file, relative to this file's folder (\"\" = built from the task's specification, "
   "corridor_length_m included)", NULL},
  {"experiment.references", X_REFS, 0, 0, 0, "optimal,example",
   "reference controllers evaluated from the same evaluation poses with the same emulator seed "
   "(controller mode = evaluate, evaluate_policy = each of these; example@GAIN = the example policy at GAIN "
   "1/s, evaluate_example_gain; \"\" = none)", NULL},
  {"experiment.vary", X_VARY, 0, 0, 0, "",
   "one sweep axis, KEY=V1|V2|...: each value of a controller or experiment key is a variant with its "
   "own result files (\"\" = no variants)", NULL},
  {"experiment.requires", X_REQUIRES, 0, 0, 0, "",
   "comma-separated controller keys the experiment needs (e.g. a learner variant of a newer "
   "controller); when one is missing the runner refuses the experiment and the sweep skips it, saying "
   "why. Put it before the lines that use those keys", NULL},
  {"experiment.explore_runs", X_INT, XOFF(explore_runs), 1, 100000, "20",
   "explore_*: independent runs per seed", NULL},
  {"experiment.explore_time_limit_s", X_DOUBLE, XOFF(explore_time_limit_s), 1, 1e8, "604800",
   "explore_*: simulated time limit of one run [s] (the paper: one week = 604800)", NULL},
  {"experiment.explore_omega_max_radps", X_DOUBLE, XOFF(explore_omega_max_radps), 0.001, 10, "1",
   "explore_*: bound of a uniform random rotation, drawn from [-max, max] [rad/s] (explore_corridor: the paper's "
   "rotation limit, its Fig. 6 sweeps it)", NULL},
  {"experiment.explore_omega_variance", X_DOUBLE, XOFF(explore_omega_variance), 0, 10, "0.05",
   "explore_*: variance of a normal random rotation N(0, variance) [rad^2/s^2] (explore_goal: the paper's 0.05)", NULL},
  {"experiment.explore_start_distance_m", X_DOUBLE, XOFF(explore_start_distance_m), 0.1, 100, "3",
   "explore_goal: start distance from the goal, pointing straight at it [m]", NULL},
  {"experiment.explore_start_x_m", X_DOUBLE, XOFF(explore_start_x_m), 0.3, 100, "1",
   "explore_corridor: start on the centre line this far from the start wall [m]; heading uniform in "
   "the half-circle towards the goal", NULL},
  {"experiment.explore_accel_limits", X_BOOL, XOFF(explore_accel_limits), 0, 0, "false",
   "explore_*: apply the B21r's acceleration limits (false: the paper's idealised model, commands take "
   "effect at once)", NULL},
  // The assumptions of the exploration studies (docs/experiments.md, the sensitivity study).
  {"experiment.explore_model", X_CHOICE, XOFF(explore_model), 0, 0, "kinematic",
   "explore_*: kinematic (the idealised model, exact state, collision test of the world's geometry) or ode "
   "(the emulated B21r of sim/env.h: the controller's command clamp with its acceleration limits, contacts, the "
   "corridor's goal declared from the laser's features; hundreds of times slower: keep its horizons short). ode "
   "supports explore_random = rotation and explore_collision = restart only", k_model_names},
  {"experiment.explore_random", X_CHOICE, XOFF(explore_random), 0, 0, "rotation",
   "explore_*: what is random: rotation (the paper's text: the rotation is random, the translation the "
   "task's own: the corridor's speed policy, the goal task's constant speed), translation (the paper's goal "
   "task writes its random variable as v_t, its symbol for the translation speed: a random translation, no "
   "rotation) or both", k_random_names},
  {"experiment.explore_rotation", X_CHOICE, XOFF(explore_rotation), 0, 0, "auto",
   "explore_*: distribution of a random rotation: uniform in [-explore_omega_max_radps, "
   "explore_omega_max_radps], or normal N(0, explore_omega_variance) clipped to explore_omega_clip_radps; "
   "auto = the paper's: uniform for explore_corridor, normal for explore_goal", k_rotation_names},
  {"experiment.explore_omega_clip_radps", X_DOUBLE, XOFF(explore_omega_clip_radps), 0, 10, "0",
   "explore_*: a normal rotation is clipped to [-clip, clip] [rad/s]; 0 = not clipped (the paper)", NULL},
  {"experiment.explore_translation", X_CHOICE, XOFF(explore_translation), 0, 0, "normal",
   "explore_*: distribution of a random translation speed: normal N(0, explore_v_variance) clipped to "
   "explore_v_clip_mps, or uniform in [-explore_v_max_mps, explore_v_max_mps]", k_translation_names},
  {"experiment.explore_v_max_mps", X_DOUBLE, XOFF(explore_v_max_mps), 0.001, 10, "0.6",
   "explore_*: bound of a uniform random translation speed [m/s]", NULL},
  {"experiment.explore_v_variance", X_DOUBLE, XOFF(explore_v_variance), 0, 10, "0.05",
   "explore_*: variance of a normal random translation speed [m^2/s^2] (the paper's 0.05)", NULL},
  {"experiment.explore_v_clip_mps", X_DOUBLE, XOFF(explore_v_clip_mps), 0, 10, "0",
   "explore_*: a normal translation speed is clipped to [-clip, clip] [m/s]; 0 = not clipped", NULL},
  {"experiment.explore_hold_s", X_DOUBLE, XOFF(explore_hold_s), 0, 1000, "0",
   "explore_*: each random draw is held this long [s] (rounded to control periods); 0 = one period, a new "
   "draw every 0.1 s (the paper's reading of a 10 Hz learner)", NULL},
  {"experiment.explore_collision", X_CHOICE, XOFF(explore_collision), 0, 0, "restart",
   "explore_*: what a collision does: restart (the attempt ends, the robot is put back at a start pose after "
   "explore_restart_s, the clock runs on) or stay (the robot stops against the wall, the move into it is "
   "refused, and it must turn away by its own random actions)", k_collision_names},
  {"experiment.explore_restart_s", X_DOUBLE, XOFF(explore_restart_s), 0, 1e6, "0",
   "explore_*: robot time a restart costs [s] (an attempt ended by a collision or the step limit): 0 = the "
   "simulation's instant reset; a stall until an operator puts the robot back costs the operator's time", NULL},
  {"experiment.explore_attempt_steps", X_INT, XOFF(explore_attempt_steps), -1, 1e9, "-1",
   "explore_*: steps after which an attempt ends without a collision and the robot is put back (a "
   "restart); -1 = the task's step limit for explore_corridor (max_steps_per_run, default 1000), none for "
   "explore_goal; 0 = none", NULL},
  {"experiment.explore_v_wall_mps", X_DOUBLE, XOFF(explore_v_wall_mps), -1, 10, "-1",
   "explore_corridor: the speed policy's speed where the robot touches a wall [m/s]; -1 = the task's (0.2)", NULL},
  {"experiment.explore_v_mps", X_DOUBLE, XOFF(explore_v_mps), -1, 10, "-1",
   "explore_*: the task's speed: the corridor's speed on the centre line, the goal task's constant speed "
   "[m/s]; -1 = the task's (0.6, 0.3)", NULL},
  {"experiment.explore_goal_size_m", X_DOUBLE, XOFF(explore_goal_size_m), -1, 100, "-1",
   "explore_*: size of the rewarding region [m]: the corridor's goal distance from the end wall, the goal "
   "task's goal radius; -1 = the task's (1.0, 0.3)", NULL},
  {"experiment.explore_start", X_CHOICE, XOFF(explore_start), 0, 0, "paper",
   "explore_*: where attempts start: paper (corridor: on the centre line at explore_start_x_m, heading "
   "uniform in the half-circle towards the goal; goal task: explore_start_distance_m from the goal pointing "
   "straight at it), any_heading (the same place, heading uniform in the full circle), training (the "
   "task's training starts, as the controller's runs)", k_start_names},
  {"experiment.explore_arena_walls", X_BOOL, XOFF(explore_arena_walls), 0, 0, "false",
   "explore_goal: the obstacle task's arena walls are there (a collision with them is handled by "
   "explore_collision); false = the paper's open plane (no obstacles, no walls)", NULL},
};
// clang-format on

#define N_XKEYS (sizeof k_xkeys / sizeof k_xkeys[0])

static const xkey_t* find_xkey(const char* name) {
  for (size_t i = 0; i < N_XKEYS; ++i) {
    if (strcmp(k_xkeys[i].name, name) == 0) {
      return &k_xkeys[i];
    }
  }
  return NULL;
}

static bool parse_num(const char* v, double* out) {
  char* end = NULL;
  errno = 0;
  const double d = strtod(v, &end);
  if (*v == '\0' || errno != 0 || end == v || *end != '\0' || !isfinite(d)) {
    return false;
  }
  *out = d;
  return true;
}

// Copies the next token of a `sep`-separated list (blanks trimmed) into out; returns the rest or NULL.
static const char* next_token(const char* p, char sep, char* out, size_t cap, bool* too_long) {
  while (*p == ' ' || *p == '\t') {
    ++p;
  }
  const char* e = strchr(p, sep);
  size_t n = e != NULL ? (size_t)(e - p) : strlen(p);
  while (n > 0 && (p[n - 1] == ' ' || p[n - 1] == '\t')) {
    --n;
  }
  *too_long = n >= cap;
  if (!*too_long) {
    memcpy(out, p, n);
    out[n] = '\0';
  }
  return e != NULL ? e + 1 : NULL;
}

bool exp_reference_example_gain(const char* name, double* gain) {
  static const char prefix[] = "example@";
  if (strncmp(name, prefix, sizeof prefix - 1) != 0) {
    return false;
  }
  // One spelling per gain: plain decimal digits with at most one point (no sign, exponent, hex,
  // spaces, or a trailing point), so two names never stand for the same gain unnoticed.
  const char* num = name + sizeof prefix - 1;
  int points = 0;
  for (const char* c = num; *c != '\0'; ++c) {
    if (*c == '.') {
      points++;
    } else if (*c < '0' || *c > '9') {
      return false;
    }
  }
  const size_t len = strlen(num);
  if (len == 0 || points > 1 || num[0] == '.' || num[len - 1] == '.') {
    return false;
  }
  char* end = NULL;
  errno = 0;
  const double g = strtod(num, &end);
  if (end == num || *end != '\0' || errno != 0 || !(g > 0.0 && g <= 100.0)) {
    return false;
  }
  if (gain != NULL) {
    *gain = g;
  }
  return true;
}

static int set_refs(exp_settings_t* s, const char* value, char* why, size_t cap) {
  exp_settings_t t = *s;
  t.n_references = 0;
  if (*value == '\0') {
    *s = t;
    return 0;
  }
  for (const char* p = value; p != NULL;) {
    char tok[sizeof t.references[0]];
    bool too_long = false;
    p = next_token(p, ',', tok, sizeof tok, &too_long);
    if (too_long) {
      fw_errfmt(why, cap, "a reference name has at most %zu characters", sizeof tok - 1);
      return -1;
    }
    double gain = 0.0;
    const bool at_gain = exp_reference_example_gain(tok, &gain);
    if (!(strcmp(tok, "optimal") == 0 || strcmp(tok, "example") == 0 || strcmp(tok, "human") == 0 || at_gain)) {
      fw_errfmt(why, cap, "'%s' is none of them (example@GAIN is the example policy at GAIN 1/s, 0 < GAIN <= 100 in "
                "plain decimals, e.g. example@2 or example@1.5; the others are values of evaluate_policy)", tok);
      return -1;
    }
    for (int32_t i = 0; i < t.n_references; ++i) {
      double other = 0.0;
      if (strcmp(t.references[i], tok) == 0 ||
          (at_gain && exp_reference_example_gain(t.references[i], &other) && !(other < gain || other > gain))) {
        fw_errfmt(why, cap, "references '%s' and '%s' are the same", t.references[i], tok);
        return -1;
      }
    }
    if (t.n_references == EXP_MAX_REFERENCES) {
      fw_errfmt(why, cap, "at most %d references", EXP_MAX_REFERENCES);
      return -1;
    }
    strcpy(t.references[t.n_references++], tok);
  }
  *s = t;
  return 0;
}

static int set_requires(exp_settings_t* s, const char* value, char* why, size_t cap) {
  s->missing[0] = '\0';
  for (const char* p = value; p != NULL && *value != '\0';) {
    char tok[64];
    bool too_long = false;
    p = next_token(p, ',', tok, sizeof tok, &too_long);
    if (too_long || tok[0] == '\0') {
      fw_errfmt(why, cap, "comma-separated key names of at most 63 characters");
      return -1;
    }
    if (!fw_config_has_key(tok)) {
      const size_t n = strlen(s->missing);
      snprintf(s->missing + n, sizeof s->missing - n, "%s%s", n > 0 ? ", " : "", tok);
    }
  }
  return 0;
}

static int set_vary(exp_settings_t* s, fw_config_t* cfg, const char* value, char* why, size_t cap) {
  exp_settings_t t = *s;
  t.n_vary = 0;
  t.vary_key[0] = '\0';
  if (*value == '\0') {
    *s = t;
    return 0;
  }
  const char* eq = strchr(value, '=');
  if (eq == NULL || eq == value || (size_t)(eq - value) >= sizeof t.vary_key) {
    fw_errfmt(why, cap, "KEY=V1|V2|... (e.g. hedger_capacity=500|2000|20000)");
    return -1;
  }
  memcpy(t.vary_key, value, (size_t)(eq - value));
  t.vary_key[eq - value] = '\0';
  for (const char* p = eq + 1; p != NULL;) {
    char tok[64];
    bool too_long = false;
    p = next_token(p, '|', tok, sizeof tok, &too_long);
    if (too_long || tok[0] == '\0' || t.n_vary == EXP_MAX_VARIANTS) {
      fw_errfmt(why, cap, "KEY=V1|V2|... with 1 to %d non-empty values of at most 63 characters", EXP_MAX_VARIANTS);
      return -1;
    }
    // Every value must be valid for its key now, not only when its task runs (unless the key
    // belongs to a controller this build does not have: the experiment is refused anyway).
    exp_settings_t probe_s = t;
    fw_config_t probe_c = *cfg;
    char inner[EXP_ERR_MAX];
    const bool missing_key = strncmp(t.vary_key, "experiment.", 11) != 0 && !fw_config_has_key(t.vary_key) &&
                             s->missing[0] != '\0';
    if (!missing_key && (strcmp(t.vary_key, "experiment.vary") == 0 ||
                         exp_set(&probe_s, &probe_c, t.vary_key, tok, "experiment.vary", inner, sizeof inner) != 0)) {
      fw_errfmt(why, cap, "value '%s' is not valid for '%s' (%s)", tok, t.vary_key, inner);
      return -1;
    }
    strcpy(t.vary_values[t.n_vary++], tok);
  }
  *s = t;
  return 0;
}

static void describe(const xkey_t* k, char* out, size_t cap) {
  switch (k->kind) {
    case X_STRING:
      snprintf(out, cap, "text of at most %u characters", EXP_STR_MAX - 1U);
      break;
    case X_CHOICE: {
      int n = snprintf(out, cap, "one of");
      for (int32_t i = 0; k->choices[i] != NULL && n >= 0 && (size_t)n < cap; ++i) {
        n += snprintf(out + n, cap - (size_t)n, "%s %s", i == 0 ? "" : ",", k->choices[i]);
      }
      break;
    }
    case X_INT:
      snprintf(out, cap, "an integer in [%.0f, %.0f]", k->min, k->max);
      break;
    case X_DOUBLE:
      snprintf(out, cap, "a number in [%g, %g]", k->min, k->max);
      break;
    case X_BOOL:
      snprintf(out, cap, "true or false");
      break;
    case X_REFS:
      snprintf(out, cap, "a comma-separated list of optimal, example, example@GAIN, human, or empty");
      break;
    case X_VARY:
      snprintf(out, cap, "KEY=V1|V2|... or empty");
      break;
    case X_REQUIRES:
      snprintf(out, cap, "comma-separated controller keys, or empty");
      break;
  }
}

static int set_xkey(exp_settings_t* s, fw_config_t* cfg, const xkey_t* k, const char* value, const char* source,
                    char* err, size_t err_cap) {
  char* field = (char*)s + k->offset;
  char why[EXP_ERR_MAX] = "";
  bool ok = false;
  switch (k->kind) {
    case X_STRING:
      if (strlen(value) < EXP_STR_MAX) {
        strcpy(field, value);
        ok = true;
      }
      break;
    case X_CHOICE:
      for (int32_t i = 0; k->choices[i] != NULL; ++i) {
        if (strcmp(value, k->choices[i]) == 0) {
          memcpy(field, &i, sizeof i);
          ok = true;
        }
      }
      break;
    case X_INT: {
      double d = 0.0;
      if (parse_num(value, &d) && !(fabs(d - floor(d)) > 0.0) && d >= k->min && d <= k->max) {
        const int32_t i = (int32_t)d;
        memcpy(field, &i, sizeof i);
        ok = true;
      }
      break;
    }
    case X_DOUBLE: {
      double d = 0.0;
      if (parse_num(value, &d) && d >= k->min && d <= k->max) {
        memcpy(field, &d, sizeof d);
        ok = true;
      }
      break;
    }
    case X_BOOL: {
      const bool t = strcmp(value, "true") == 0;
      if (t || strcmp(value, "false") == 0) {
        memcpy(field, &t, sizeof t);
        ok = true;
      }
      break;
    }
    case X_REFS:
      ok = set_refs(s, value, why, sizeof why) == 0;
      break;
    case X_VARY:
      ok = set_vary(s, cfg, value, why, sizeof why) == 0;
      break;
    case X_REQUIRES:
      ok = set_requires(s, value, why, sizeof why) == 0;
      break;
  }
  if (ok) {
    return 0;
  }
  char allowed[128];
  describe(k, allowed, sizeof allowed);
  fw_errfmt(err, err_cap, "%s: bad value '%s' for key '%s': expected %s%s%s (default \"%s\")", source, value, k->name,
      allowed, why[0] != '\0' ? ": " : "", why, k->def);
  return -1;
}

void exp_settings_defaults(exp_settings_t* s) {
  memset(s, 0, sizeof *s);
  fw_config_t unused;
  fw_config_defaults(&unused);
  for (size_t i = 0; i < N_XKEYS; ++i) {
    (void)set_xkey(s, &unused, &k_xkeys[i], k_xkeys[i].def, "default", NULL, 0);
  }
}

int exp_set(exp_settings_t* s, fw_config_t* cfg, const char* key, const char* value, const char* source, char* err,
            size_t err_cap) {
  if (strncmp(key, "experiment.", 11) == 0) {
    const xkey_t* k = find_xkey(key);
    if (k == NULL) {
      fw_errfmt(err, err_cap, "%s: unknown key '%s' (b21r-experiment --print-reference-config lists every key)", source,
          key);
      return -1;
    }
    return set_xkey(s, cfg, k, value, source, err, err_cap);
  }
  return fw_config_set(cfg, key, value, source, err, err_cap);
}

static int extra_key(void* user, const char* key, const char* value, const char* source, char* err, size_t err_cap) {
  if (strncmp(key, "experiment.", 11) != 0) {
    return 1;
  }
  void** both = (void**)user;
  return exp_set((exp_settings_t*)both[0], (fw_config_t*)both[1], key, value, source, err, err_cap);
}

int exp_load_file(exp_settings_t* s, fw_config_t* cfg, const char* path, char* err, size_t err_cap) {
  void* both[2] = {s, cfg};
  if (fw_config_load_file_with(cfg, path, extra_key, both, err, err_cap) != 0) {
    return -1;
  }
  char copy[EXP_STR_MAX];
  if (strlen(path) >= sizeof copy) {
    fw_errfmt(err, err_cap, "%s: path longer than %u characters", path, EXP_STR_MAX - 1U);
    return -1;
  }
  strcpy(copy, path);
  snprintf(s->config_dir, sizeof s->config_dir, "%s", dirname(copy));
  if (s->name[0] == '\0') {
    strcpy(copy, path);
    char* base = basename(copy);
    char* dot = strrchr(base, '.');
    if (dot != NULL && strcmp(dot, ".conf") == 0) {
      *dot = '\0';
    }
    snprintf(s->name, sizeof s->name, "%s", base);
  }
  return 0;
}

int exp_validate(const exp_settings_t* s, const fw_config_t* cfg, char* err, size_t err_cap) {
  if (fw_config_validate(cfg, err, err_cap) != 0) {
    return -1;
  }
  for (const char* p = s->name; *p != '\0'; ++p) {
    if (!((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z') || (*p >= '0' && *p <= '9') || *p == '_' ||
          *p == '-' || *p == '.')) {
      fw_errfmt(err, err_cap, "experiment.name '%s': use letters, digits, '_', '-' and '.' only (it names a folder)",
          s->name);
      return -1;
    }
  }
  // Every variant must pass the controller's checks across keys too (e.g. a reversed
  // example_gain_range), now rather than when its task runs.
  for (int32_t i = 0; i < s->n_vary; ++i) {
    exp_settings_t probe_s = *s;
    fw_config_t probe_c = *cfg;
    char source[EXP_ERR_MAX];
    snprintf(source, sizeof source, "experiment.vary (variant %s=%s)", s->vary_key, s->vary_values[i]);
    if (exp_set(&probe_s, &probe_c, s->vary_key, s->vary_values[i], source, err, err_cap) != 0 ||
        fw_config_validate(&probe_c, err, err_cap) != 0) {
      return -1;
    }
  }
  if (s->kind == EXP_LEARN && cfg->mode != FW_MODE_LEARN) {
    fw_errfmt(err, err_cap, "experiment.kind = learn needs mode = learn (references are evaluated by the runner)");
    return -1;
  }
  if (s->kind == EXP_LEARN && cfg->phase_driver == FW_DRIVER_JOYSTICK) {
    fw_errfmt(err, err_cap,
        "phase_one_driver = joystick needs a person; experiments use example or human (the simulated driver)");
    return -1;
  }
  if (s->kind == EXP_EXPLORE_CORRIDOR && strcmp(fw_task_name(cfg->task), "corridor") != 0) {
    fw_errfmt(err, err_cap, "experiment.kind = explore_corridor needs task = corridor");
    return -1;
  }
  if (s->kind == EXP_EXPLORE_GOAL && strcmp(fw_task_name(cfg->task), "obstacles") != 0) {
    fw_errfmt(err, err_cap, "experiment.kind = explore_goal needs task = obstacles (the goal task, without obstacles)");
    return -1;
  }
  if (s->kind != EXP_LEARN && s->explore_model == EXP_MODEL_ODE &&
      (s->explore_collision != EXP_COLLISION_RESTART || s->explore_random != EXP_RANDOM_ROTATION)) {
    fw_errfmt(err, err_cap,
        "experiment.explore_model = ode supports explore_collision = restart and explore_random = rotation only "
        "(the emulator's runs end at a contact and drive at the task's speed); use explore_model = kinematic");
    return -1;
  }
  return 0;
}

void exp_print_reference(FILE* out) {
  fprintf(out, "# --- Experiment (b21r-experiment); every other key is the controller's ---\n");
  for (size_t i = 0; i < N_XKEYS; ++i) {
    char allowed[128];
    describe(&k_xkeys[i], allowed, sizeof allowed);
    fprintf(out, "# %s\n#   allowed: %s\n%s = \"%s\"\n", k_xkeys[i].doc, allowed, k_xkeys[i].name, k_xkeys[i].def);
  }
}

int exp_resolve_path(const exp_settings_t* s, const char* path, char* out, size_t cap) {
  const int n = path[0] == '/' || s->config_dir[0] == '\0' ? snprintf(out, cap, "%s", path)
                                                           : snprintf(out, cap, "%s/%s", s->config_dir, path);
  return n < 0 || (size_t)n >= cap ? -1 : 0;
}

// ---- JSON ---------------------------------------------------------------------------------

void json_begin(json_writer_t* w, FILE* f) {
  w->f = f;
  w->depth = 0;
  w->first[0] = true;
}

static void json_escape(FILE* f, const char* s) {
  fputc('"', f);
  for (const unsigned char* p = (const unsigned char*)s; *p != '\0'; ++p) {
    if (*p == '"' || *p == '\\') {
      fprintf(f, "\\%c", *p);
    } else if (*p < 0x20) {
      fprintf(f, "\\u%04x", *p);
    } else {
      fputc(*p, f);
    }
  }
  fputc('"', f);
}

static void json_key(json_writer_t* w, const char* key) {
  if (!w->first[w->depth]) {
    fputc(',', w->f);
  }
  w->first[w->depth] = false;
  if (key != NULL) {
    json_escape(w->f, key);
    fputc(':', w->f);
  }
}

static void json_open(json_writer_t* w, const char* key, char c) {
  json_key(w, key);
  fputc(c, w->f);
  if (w->depth + 1 < (int)(sizeof w->first / sizeof w->first[0])) {
    w->depth++;
  }
  w->first[w->depth] = true;
}

void json_object(json_writer_t* w, const char* key) { json_open(w, key, '{'); }
void json_array(json_writer_t* w, const char* key) { json_open(w, key, '['); }

void json_end_object(json_writer_t* w) {
  fputc('}', w->f);
  w->depth--;
  if (w->depth == 0) {
    fputc('\n', w->f);
  }
}

void json_end_array(json_writer_t* w) {
  fputc(']', w->f);
  w->depth--;
}

void json_int(json_writer_t* w, const char* key, int64_t v) {
  json_key(w, key);
  fprintf(w->f, "%lld", (long long)v);
}

void json_num(json_writer_t* w, const char* key, double v) {
  json_key(w, key);
  if (isfinite(v)) {
    fprintf(w->f, "%.10g", v);
  } else {
    fputs("null", w->f);
  }
}

void json_bool(json_writer_t* w, const char* key, bool v) {
  json_key(w, key);
  fputs(v ? "true" : "false", w->f);
}

void json_null(json_writer_t* w, const char* key) {
  json_key(w, key);
  fputs("null", w->f);
}

void json_str(json_writer_t* w, const char* key, const char* v) {
  json_key(w, key);
  json_escape(w->f, v);
}

// ---- result files -------------------------------------------------------------------------

void exp_write_header(json_writer_t* w, const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task) {
  json_str(w, "format", "b21r-experiment-result/1");
  json_str(w, "experiment", s->name);
  json_str(w, "title", s->title);
  json_str(w, "kind", k_kind_names[s->kind]);
  json_str(w, "variant", task->variant);
  // Position of the variant in experiment.vary (the first is the baseline of comparisons).
  int32_t index = 0;
  for (int32_t i = 0; i < s->n_vary; ++i) {
    char label[160];
    snprintf(label, sizeof label, "%s=%s", s->vary_key, s->vary_values[i]);
    if (strcmp(label, task->variant) == 0) {
      index = i;
    }
  }
  json_int(w, "variant_index", index);
  json_int(w, "seed", (int64_t)task->seed);
  json_str(w, "command", task->command_line);
  // Every controller setting as the controller prints it, so a result names exactly what ran.
  json_object(w, "controller");
  char* text = NULL;
  size_t len = 0;
  FILE* mem = open_memstream(&text, &len);
  if (mem != NULL) {
    fw_config_print(cfg, mem);
    fclose(mem);
    for (char* line = strtok(text, "\n"); line != NULL; line = strtok(NULL, "\n")) {
      char* eq = strstr(line, " = ");
      if (eq == NULL) {
        continue;
      }
      *eq = '\0';
      char* v = eq + 3;
      const size_t n = strlen(v);
      if (n >= 2 && v[0] == '"' && v[n - 1] == '"') {
        v[n - 1] = '\0';
        ++v;
      }
      json_str(w, line, v);
    }
    free(text);
  }
  json_end_object(w);
}

FILE* exp_open_result(const char* path, char* tmp_path, size_t tmp_cap, char* err, size_t err_cap) {
  if (snprintf(tmp_path, tmp_cap, "%s.tmp", path) >= (int)tmp_cap) {
    fw_errfmt(err, err_cap, "%s: path too long", path);
    return NULL;
  }
  FILE* f = fopen(tmp_path, "w");
  if (f == NULL) {
    fw_errfmt(err, err_cap, "%s: cannot create: %s (does its folder exist?)", tmp_path, strerror(errno));
  }
  return f;
}

int exp_commit_result(FILE* f, const char* tmp_path, const char* path, char* err, size_t err_cap) {
  const bool bad = ferror(f) != 0 || fflush(f) != 0 || fsync(fileno(f)) != 0;
  if (fclose(f) != 0 || bad) {
    fw_errfmt(err, err_cap, "%s: write failed: %s", tmp_path, strerror(errno));
    (void)unlink(tmp_path);
    return -1;
  }
  if (rename(tmp_path, path) != 0) {
    fw_errfmt(err, err_cap, "%s: cannot rename to %s: %s", tmp_path, path, strerror(errno));
    (void)unlink(tmp_path);
    return -1;
  }
  return 0;
}
