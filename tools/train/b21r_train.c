// SPDX-License-Identifier: MIT
// b21r-train: trains HEDGER offline from experience logs and writes a controller checkpoint.
#include "train.h"

#include <fw/config.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { EXIT_FAIL = 1, EXIT_USAGE = 2 };

static void usage(FILE* f) {
  fprintf(f,
          "usage: b21r-train [--config FILE]... [--set KEY=VALUE]... --out CHECKPOINT [options] LOG...\n"
          "Trains HEDGER offline from the B21R_EXPERIENCE messages of LCM event logs (the controller's\n"
          "--log / --experience-log files, lcm-logger recordings), whoever drove (example policy,\n"
          "joystick, learned policy), and writes a checkpoint from which b21r-controller, started with\n"
          "the same configuration and --checkpoint CHECKPOINT, resumes in phase two.\n"
          "\n"
          "  --config FILE    controller settings, as b21r-controller reads them (several apply in order)\n"
          "  --set KEY=VALUE  override one setting (after the files); the HEDGER settings (hedger_*, alpha,\n"
          "                   gamma, task, max_rotation_radps, seed, hedger_replay) are derived exactly as\n"
          "                   the controller derives them: give the controller's file\n"
          "  --out FILE       checkpoint to write (atomically)\n"
          "  --force          replace --out if it exists\n"
          "  --init FILE      start from the learned state of this checkpoint instead of an empty one\n"
          "  --include-eval   also learn from evaluation runs (the controller does not: learning is off there)\n"
          "  --passes N       train N times over all logs, in order (default 1: what the controller did)\n"
          "  --channel NAME   experience channel (default B21R_EXPERIENCE)\n"
          "  --quiet          no progress lines on stderr\n"
          "  --help           this text\n"
          "\n"
          "Logs are learned in the order given, each streamed in file order; a run ends where its run id\n"
          "changes, the controller restarted, or the log ends. At the end a summary line gives the\n"
          "experiences per second. Exit status: 0 done; 1 a log or the checkpoint failed; 2 usage.\n");
}

int main(int argc, char** argv) {
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  char err[TRAIN_ERR_MAX];
  train_options_t opt = {.include_eval = false, .channel = NULL, .progress = stderr, .progress_period_s = 1.0};
  const char* out = NULL;
  const char* init = NULL;
  bool force = false;
  long passes = 1;
  const char** logs = (const char**)calloc((size_t)argc, sizeof *logs);
  int n_logs = 0;
  if (logs == NULL) {
    return EXIT_FAIL;
  }

  // As b21r-controller: config files first, in order; then everything else, in order.
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
      usage(stdout);
      free(logs);
      return 0;
    }
    if (strcmp(argv[i], "--config") == 0) {
      if (i + 1 >= argc) {
        snprintf(err, sizeof err, "--config needs a file");
      } else if (fw_config_load_file(&cfg, argv[++i], err, sizeof err) == 0) {
        continue;
      }
      fprintf(stderr, "b21r-train: %s\n", err);
      free(logs);
      return EXIT_USAGE;
    }
  }
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const bool has_value = i + 1 < argc;
    const char* v = has_value ? argv[i + 1] : NULL;
    int rc = 0;
    if (strcmp(a, "--config") == 0) {
      ++i;
    } else if (strcmp(a, "--include-eval") == 0) {
      opt.include_eval = true;
    } else if (strcmp(a, "--force") == 0) {
      force = true;
    } else if (strcmp(a, "--quiet") == 0) {
      opt.progress = NULL;
    } else if (strcmp(a, "--set") == 0 || strcmp(a, "--out") == 0 || strcmp(a, "--init") == 0 ||
               strcmp(a, "--passes") == 0 || strcmp(a, "--channel") == 0) {
      if (!has_value) {
        fprintf(stderr, "b21r-train: %s needs an argument (see --help)\n", a);
        free(logs);
        return EXIT_USAGE;
      }
      ++i;
      if (strcmp(a, "--set") == 0) {
        rc = fw_config_set_arg(&cfg, v, err, sizeof err);
      } else if (strcmp(a, "--out") == 0) {
        out = v;
      } else if (strcmp(a, "--init") == 0) {
        init = v;
      } else if (strcmp(a, "--channel") == 0) {
        opt.channel = v;
      } else {
        char* end = NULL;
        passes = strtol(v, &end, 10);
        if (*v == '\0' || *end != '\0' || passes < 1 || passes > 1000) {
          snprintf(err, sizeof err, "--passes %s: expected an integer in [1, 1000]", v);
          rc = -1;
        }
      }
    } else if (a[0] == '-' && a[1] != '\0') {
      fprintf(stderr, "b21r-train: unknown option '%s' (see --help)\n", a);
      free(logs);
      return EXIT_USAGE;
    } else {
      logs[n_logs++] = a;
    }
    if (rc != 0) {
      fprintf(stderr, "b21r-train: %s\n", err);
      free(logs);
      return EXIT_USAGE;
    }
  }
  if (out == NULL || n_logs == 0) {
    fprintf(stderr, "b21r-train: %s (see --help)\n", out == NULL ? "--out CHECKPOINT is required" : "no LOG given");
    free(logs);
    return EXIT_USAGE;
  }
  if (fw_config_validate(&cfg, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-train: %s\n", err);
    free(logs);
    return EXIT_USAGE;
  }

  err[0] = '\0';
  trainer_t* t = trainer_create(&cfg, &opt, err, sizeof err);
  int status = t == NULL ? EXIT_FAIL : 0;
  if (status == 0 && init != NULL && trainer_load_checkpoint(t, init, err, sizeof err) != 0) {
    status = EXIT_FAIL;
  }
  for (long p = 0; status == 0 && p < passes; ++p) {
    for (int i = 0; status == 0 && i < n_logs; ++i) {
      if (trainer_add_log(t, logs[i], err, sizeof err) != 0) {
        status = EXIT_FAIL;
      }
    }
  }
  if (status == 0) {
    trainer_finish(t);
    const train_stats_t s = trainer_stats(t);
    const hedger_counters_t* c = hedger_counters(trainer_hedger(t));
    const hedger_config_t* hc = hedger_get_config(trainer_hedger(t));
    printf("b21r-train: %llu experiences learned from %d log(s) x %ld pass(es), %llu runs (%llu replayed updates), "
           "store %u/%u, in %.3f s: %.0f experiences/s (%.0f updates/s)\n",
           (unsigned long long)s.used, n_logs, passes, (unsigned long long)s.runs, (unsigned long long)s.replayed,
           c->store_fill, hc->capacity, s.seconds, s.seconds > 0.0 ? (double)s.used / s.seconds : 0.0,
           s.seconds > 0.0 ? (double)(s.used + s.replayed) / s.seconds : 0.0);
    if (s.skipped_eval > 0) {
      printf("b21r-train: %llu experiences of evaluation runs left out (--include-eval learns them too)\n",
             (unsigned long long)s.skipped_eval);
    }
    if (s.init_legacy_shift) {
      fprintf(stderr,
              "b21r-train: note: %s was written by an older controller whose learned policy added a shift learned "
              "from ranked pairs of runs; its learned values are trained on, and the output holds no shift\n",
              init);
    }
    if (s.init_actor_cloned > 0) {
      fprintf(stderr,
              "b21r-train: note: %s holds no actor (policy = greedy or an older controller): the actor started as "
              "the policy of its %u stored points (behaviour cloning), then learned from the logs\n",
              init, s.init_actor_cloned);
    }
    if (s.init_actor_dropped) {
      fprintf(stderr, "b21r-train: note: %s holds an actor that policy = greedy does not use: the output holds none\n",
              init);
    }
    if (s.seq_gaps > 0 || s.refused > 0 || s.undecodable > 0) {
      fprintf(stderr,
              "b21r-train: warning: %llu gaps in the experiences' seq (the recording lost messages), %llu experiences "
              "refused (non-finite), %llu messages not decodable\n",
              (unsigned long long)s.seq_gaps, (unsigned long long)s.refused, (unsigned long long)s.undecodable);
    }
    if (s.used == 0) {
      snprintf(err, sizeof err, "no experience learned (none on channel %s%s)",
               opt.channel != NULL ? opt.channel : "B21R_EXPERIENCE",
               s.skipped_eval > 0 ? " outside evaluation runs" : "");
      status = EXIT_FAIL;
    } else if (trainer_write_checkpoint(t, out, force, err, sizeof err) != 0) {
      status = EXIT_FAIL;
    } else {
      printf("b21r-train: wrote %s: b21r-controller resumes in phase two from it (--checkpoint %s, the same "
             "configuration)\n",
             out, out);
    }
  }
  if (status != 0) {
    fprintf(stderr, "b21r-train: %s\n", err);
  }
  trainer_destroy(t);
  free(logs);
  return status;
}
