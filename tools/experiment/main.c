// SPDX-License-Identifier: MIT
// b21r-experiment: runs one (experiment, variant, seed) of the paper's experiments and writes its
// result file; or prints an experiment's plan (seeds x variants) for a sweep (see experiment.h).
#define _POSIX_C_SOURCE 200809L
#include "experiment.h"

#include <stdlib.h>
#include <string.h>

static void usage(FILE* f) {
  fprintf(f,
          "usage: b21r-experiment --config FILE [--set KEY=VALUE]... [--variant KEY=VALUE] --seed N --out RESULT.json\n"
          "                       [--experience-log FILE] [--trace-svg FILE] [--verbose]\n"
          "       b21r-experiment --config FILE [--set KEY=VALUE]... --plan\n"
          "       b21r-experiment --print-reference-config\n"
          "Runs one seed of one experiment of the paper (Smart & Kaelbling, ICRA 2002) and writes its\n"
          "result (JSON, atomically). Kind learn: the controller's loop core and the ODE emulator of the\n"
          "B21r in one process, then the reference controllers from the same evaluation poses. Kinds\n"
          "explore_corridor / explore_goal: random exploration on the idealised kinematic model.\n"
          "\n"
          "  --config FILE          experiment file: controller keys (b21r-controller --print-reference-config)\n"
          "                         and experiment.* keys (--print-reference-config below)\n"
          "  --set KEY=VALUE        override a controller or experiment key (after the file)\n"
          "  --variant KEY=VALUE    like --set, and names the result's variant (one value of experiment.vary)\n"
          "  --seed N               the seed: controller seed and emulator seed\n"
          "  --out FILE             result file (written as FILE.tmp, then renamed)\n"
          "  --experience-log FILE  also write B21R_EXPERIENCE as an LCM event log (kind learn), byte for\n"
          "                         byte what b21r-controller --experience-log writes for the same run\n"
          "  --trace-svg FILE       overhead picture of the learning session's runs (kind learn)\n"
          "  --verbose              the controller's progress lines on stderr\n"
          "  --plan                 print the sweep plan as JSON: name, kind, seeds, variants\n"
          "Exit status: 0 done; 1 the experiment failed (message on stderr); 2 usage or configuration error;\n"
          "3 the experiment needs controller keys this build does not have (experiment.requires).\n");
}

static int print_plan(const exp_settings_t* s) {
  static const char* const kinds[] = {"learn", "explore_corridor", "explore_goal"};
  json_writer_t w;
  json_begin(&w, stdout);
  json_object(&w, NULL);
  json_str(&w, "name", s->name);
  json_str(&w, "kind", kinds[s->kind]);
  json_str(&w, "title", s->title);
  if (s->missing[0] != '\0') {
    char why[EXP_STR_MAX + 96];
    snprintf(why, sizeof why, "needs the controller key(s) %s, which this build does not have", s->missing);
    json_str(&w, "unavailable", why);
  }
  json_array(&w, "seeds");
  for (int32_t i = 0; i < s->seeds; ++i) {
    json_int(&w, NULL, s->first_seed + i);
  }
  json_end_array(&w);
  json_array(&w, "variants");
  if (s->n_vary == 0) {
    json_str(&w, NULL, "");
  }
  for (int32_t i = 0; i < s->n_vary; ++i) {
    char label[160];
    snprintf(label, sizeof label, "%s=%s", s->vary_key, s->vary_values[i]);
    json_str(&w, NULL, label);
  }
  json_end_array(&w);
  json_end_object(&w);
  return 0;
}

int main(int argc, char** argv) {
  exp_settings_t s;
  exp_settings_defaults(&s);
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  char err[EXP_ERR_MAX];
  const char* config = NULL;
  const char* variant = "";
  const char* out = NULL;
  const char* exp_log = NULL;
  const char* svg = NULL;
  bool plan = false;
  bool verbose = false;
  long long seed = -1;

  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
      usage(stdout);
      return 0;
    }
    if (strcmp(argv[i], "--print-reference-config") == 0) {
      exp_print_reference(stdout);
      return 0;
    }
    if (strcmp(argv[i], "--config") == 0 && i + 1 < argc) {
      config = argv[++i];
    }
  }
  if (config == NULL) {
    fprintf(stderr, "b21r-experiment: --config FILE is required (see --help)\n");
    return 2;
  }
  if (exp_load_file(&s, &cfg, config, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-experiment: %s\n", err);
    return 2;
  }
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const char* v = i + 1 < argc ? argv[i + 1] : NULL;
    const bool takes = strcmp(a, "--config") == 0 || strcmp(a, "--set") == 0 || strcmp(a, "--variant") == 0 ||
                       strcmp(a, "--seed") == 0 || strcmp(a, "--out") == 0 || strcmp(a, "--experience-log") == 0 ||
                       strcmp(a, "--trace-svg") == 0;
    if (takes && v == NULL) {
      fprintf(stderr, "b21r-experiment: %s needs an argument (see --help)\n", a);
      return 2;
    }
    if (strcmp(a, "--set") == 0 || strcmp(a, "--variant") == 0) {
      char kv[512];
      snprintf(kv, sizeof kv, "%s", v);
      char* eq = strchr(kv, '=');
      if (eq == NULL) {
        fprintf(stderr, "b21r-experiment: %s '%s': expected KEY=VALUE\n", a, v);
        return 2;
      }
      *eq = '\0';
      if (exp_set(&s, &cfg, kv, eq + 1, a, err, sizeof err) != 0) {
        fprintf(stderr, "b21r-experiment: %s\n", err);
        return 2;
      }
      if (strcmp(a, "--variant") == 0) {
        variant = v;
      }
    } else if (strcmp(a, "--seed") == 0) {
      char* end = NULL;
      seed = strtoll(v, &end, 10);
      if (*v == '\0' || *end != '\0' || seed < 0) {
        fprintf(stderr, "b21r-experiment: --seed '%s': expected a non-negative integer\n", v);
        return 2;
      }
    } else if (strcmp(a, "--out") == 0) {
      out = v;
    } else if (strcmp(a, "--experience-log") == 0) {
      exp_log = v;
    } else if (strcmp(a, "--trace-svg") == 0) {
      svg = v;
    } else if (strcmp(a, "--plan") == 0) {
      plan = true;
      continue;
    } else if (strcmp(a, "--verbose") == 0) {
      verbose = true;
      continue;
    } else if (strcmp(a, "--config") != 0) {
      fprintf(stderr, "b21r-experiment: unknown argument '%s' (see --help)\n", a);
      return 2;
    }
    ++i;
  }
  if (s.missing[0] == '\0' && exp_validate(&s, &cfg, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-experiment: %s: %s\n", config, err);
    return 2;
  }
  if (plan) {
    return print_plan(&s);
  }
  if (s.missing[0] != '\0') {
    fprintf(stderr, "b21r-experiment: %s: needs the controller key(s) %s, which this build does not have\n", config,
            s.missing);
    return 3;
  }
  if (seed < 0 || out == NULL) {
    fprintf(stderr, "b21r-experiment: --seed N and --out FILE are required (see --help)\n");
    return 2;
  }
  char command[4096];
  size_t used = 0;
  for (int i = 0; i < argc && used < sizeof command; ++i) {
    used += (size_t)snprintf(command + used, sizeof command - used, "%s%s", i == 0 ? "" : " ", argv[i]);
  }
  const exp_task_t task = {.variant = variant,
                           .seed = (uint64_t)seed,
                           .out_path = out,
                           .experience_log = exp_log,
                           .trace_svg = svg,
                           .verbose = verbose,
                           .command_line = command};
  const int rc = s.kind == EXP_LEARN ? exp_run_learn(&s, &cfg, &task, err, sizeof err)
                                     : exp_run_explore(&s, &cfg, &task, err, sizeof err);
  if (rc != 0) {
    fprintf(stderr, "b21r-experiment: %s (seed %lld%s%s): %s\n", s.name, seed, variant[0] != '\0' ? ", " : "",
            variant, err);
    return 1;
  }
  return 0;
}
