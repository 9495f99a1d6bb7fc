// SPDX-License-Identifier: MIT
// b21r-sim: the emulated B21r behind pseudo-terminals and SOCK_SEQPACKET sockets.
#define _GNU_SOURCE  // getopt_long, signalfd, accept4
#include <errno.h>
#include <getopt.h>
#include <linux/can/error.h>
#include <inttypes.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "sim/emulator.h"
#include "sim/endpoints.h"

#define APP_MAX_CLIENTS 8
#define APP_PEND_BYTES (1U << 20)  // per serial line: output held back (latency, slow reader)
#define APP_PEND_CHUNKS 8192U
#define APP_PEND_FRAMES 8192U

// Output waiting for its (latency-delayed) time and for the reader: a byte ring + chunk ring.
typedef struct pend {
  uint8_t bytes[APP_PEND_BYTES];
  size_t head, len;
  struct {
    uint64_t ready_ns;
    uint32_t n;
  } ch[APP_PEND_CHUNKS];
  size_t ch_head, ch_len;
  uint64_t dropped;
} pend_t;

typedef struct frame_pend {
  struct {
    uint64_t ready_ns;
    struct can_frame f;
  } fr[APP_PEND_FRAMES];
  size_t head, len;
  uint64_t dropped;
} frame_pend_t;

typedef struct options {
  const char* world;
  const char* control;
  const char* can;
  const char* endpoints;
  const char* trace_svg;
  const char* can_log;
  const char* can_log_iface;
  sim_emu_config_t cfg;
  int start_index;
  int have_start;
  double start_x, start_y, start_th;
} options_t;

// All of the program's state: one context, no file statics.
typedef struct app {
  options_t opt;
  sim_world_t world;
  sim_emu_t* emu;
  int laser_master, laser_slave;
  int base_master, base_slave;
  int can_listen;
  int can_clients[APP_MAX_CLIENTS];
  int ctl_listen;
  int ctl_clients[APP_MAX_CLIENTS];
  int sig_fd;
  char laser_path[64], base_path[64];
  char can_path[256];
  pend_t laser_out, base_out;
  frame_pend_t can_out;
  FILE* can_log;            // candump -L trace of the bus (--can-log), or NULL
  uint64_t can_log_flush_ns;
  uint64_t t0_ns;
  int quit;
  uint8_t io[65536];
} app_t;

static uint64_t mono_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (uint64_t)ts.tv_sec * 1000000000ULL + (uint64_t)ts.tv_nsec;
}

static void usage(FILE* f) {
  fprintf(f,
          "usage: b21r-sim --world FILE [options]\n"
          "The emulated RWI B21r (rFLEX base or CiA 402 drives, SICK LMS200) on ODE.\n"
          "\n"
          "  --world FILE          world file (sim/worlds/*.world; format in sim/world.h)\n"
          "  --lockstep            advance one control period per command cycle (deterministic)\n"
          "  --realtime            run on the monotonic clock (default)\n"
          "  --base rflex|canopen  base interface (default rflex)\n"
          "  --control PATH        control socket (SOCK_SEQPACKET; reset, pose, fault, status,\n"
          "                        svg, quit)\n"
          "  --can PATH            CAN bus socket (canopen; default PATH of --control + \".can\")\n"
          "  --can-log FILE        write every frame on the CAN bus to FILE in candump -L format\n"
          "                        ('(seconds) vcan0 181#2702...'), for cantools decode, canplayer\n"
          "  --can-log-iface NAME  interface name written in the trace (default vcan0)\n"
          "  --endpoints FILE      also write the ready line to FILE (atomically)\n"
          "  --seed N              seed of every random stream (default 1)\n"
          "  --period S            control period in seconds (default 0.1)\n"
          "  --dt S                ODE substep in seconds (default 0.01)\n"
          "  --start X,Y,THETA     start pose (default: the world's first start)\n"
          "  --start-index N       start at the world's N-th start pose (0-based)\n"
          "  --laser-baud N        LMS200 power-up baud rate: 9600 (default), 19200, 38400, 500000\n"
          "  --laser-variant W/R   power-up variant: 180/1 (default), 180/0.5, 100/1, 100/0.5, 100/0.25\n"
          "  --laser-unit mm|cm    power-up distance unit (default mm)\n"
          "  --laser-noise SIGMA   range noise standard deviation in metres (default 0.005)\n"
          "  --laser-x M           laser mount, metres ahead of the centre (default 0.15)\n"
          "  --watchdog S          rFLEX command watchdog in seconds, 0 = off (default 1)\n"
          "  --brake-released      rFLEX brake released at power-up (default engaged)\n"
          "  --trace-svg FILE      write an overhead picture of the run(s) at exit\n"
          "  --help                this text\n"
          "\n"
          "When ready it prints one line 'laser=/dev/pts/N base=/dev/pts/M can=PATH control=PATH'\n"
          "(the fields that apply). Contract: sim/include/sim/emulator.h and sim/README.md.\n");
}

static int parse_double(const char* s, double* out) {
  char* end = NULL;
  errno = 0;
  const double v = strtod(s, &end);
  if (end == s || *end != '\0' || errno != 0 || !isfinite(v)) {
    return -1;
  }
  *out = v;
  return 0;
}

static int parse_args(int argc, char** argv, options_t* o) {
  enum {
    OPT_WORLD = 1000, OPT_LOCKSTEP, OPT_REALTIME, OPT_BASE, OPT_CONTROL, OPT_CAN, OPT_ENDPOINTS,
    OPT_SEED, OPT_PERIOD, OPT_DT, OPT_START, OPT_START_INDEX, OPT_BAUD, OPT_VARIANT, OPT_UNIT,
    OPT_NOISE, OPT_LASER_X, OPT_WATCHDOG, OPT_BRAKE, OPT_SVG, OPT_CAN_LOG, OPT_CAN_LOG_IFACE, OPT_HELP,
  };
  static const struct option longopts[] = {
      {"world", required_argument, NULL, OPT_WORLD},
      {"lockstep", no_argument, NULL, OPT_LOCKSTEP},
      {"realtime", no_argument, NULL, OPT_REALTIME},
      {"base", required_argument, NULL, OPT_BASE},
      {"control", required_argument, NULL, OPT_CONTROL},
      {"can", required_argument, NULL, OPT_CAN},
      {"endpoints", required_argument, NULL, OPT_ENDPOINTS},
      {"seed", required_argument, NULL, OPT_SEED},
      {"period", required_argument, NULL, OPT_PERIOD},
      {"dt", required_argument, NULL, OPT_DT},
      {"start", required_argument, NULL, OPT_START},
      {"start-index", required_argument, NULL, OPT_START_INDEX},
      {"laser-baud", required_argument, NULL, OPT_BAUD},
      {"laser-variant", required_argument, NULL, OPT_VARIANT},
      {"laser-unit", required_argument, NULL, OPT_UNIT},
      {"laser-noise", required_argument, NULL, OPT_NOISE},
      {"laser-x", required_argument, NULL, OPT_LASER_X},
      {"watchdog", required_argument, NULL, OPT_WATCHDOG},
      {"brake-released", no_argument, NULL, OPT_BRAKE},
      {"trace-svg", required_argument, NULL, OPT_SVG},
      {"can-log", required_argument, NULL, OPT_CAN_LOG},
      {"can-log-iface", required_argument, NULL, OPT_CAN_LOG_IFACE},
      {"help", no_argument, NULL, OPT_HELP},
      {NULL, 0, NULL, 0},
  };
  memset(o, 0, sizeof(*o));
  sim_emu_config_default(&o->cfg);
  o->cfg.mode = SIM_MODE_REALTIME;
  o->start_index = -1;
  int c;
  while ((c = getopt_long(argc, argv, "", longopts, NULL)) != -1) {
    double v = 0.0;
    const char* a = optarg;
    switch (c) {
      case OPT_WORLD: o->world = a; break;
      case OPT_LOCKSTEP: o->cfg.mode = SIM_MODE_LOCKSTEP; break;
      case OPT_REALTIME: o->cfg.mode = SIM_MODE_REALTIME; break;
      case OPT_BASE:
        if (strcmp(a, "rflex") == 0) {
          o->cfg.base = SIM_BASE_RFLEX;
        } else if (strcmp(a, "canopen") == 0) {
          o->cfg.base = SIM_BASE_CANOPEN;
        } else {
          fprintf(stderr, "b21r-sim: --base must be rflex or canopen, not '%s'\n", a);
          return -1;
        }
        break;
      case OPT_CONTROL: o->control = a; break;
      case OPT_CAN: o->can = a; break;
      case OPT_ENDPOINTS: o->endpoints = a; break;
      case OPT_SVG: o->trace_svg = a; break;
      case OPT_CAN_LOG: o->can_log = a; break;
      case OPT_CAN_LOG_IFACE: {
        // candump's names: letters and digits (what its log readers accept), at most IFNAMSIZ-1.
        size_t len = strlen(a);
        int ok = len > 0 && len < 16;
        for (size_t i = 0; ok && i < len; ++i) {
          ok = (a[i] >= 'a' && a[i] <= 'z') || (a[i] >= 'A' && a[i] <= 'Z') || (a[i] >= '0' && a[i] <= '9');
        }
        if (!ok) {
          fprintf(stderr, "b21r-sim: --can-log-iface needs 1 to 15 letters or digits, not '%s'\n", a);
          return -1;
        }
        o->can_log_iface = a;
        break;
      }
      case OPT_SEED: {
        char* end = NULL;
        errno = 0;
        const unsigned long long s = strtoull(a, &end, 0);
        if (end == a || *end != '\0' || errno != 0) {
          fprintf(stderr, "b21r-sim: --seed needs an unsigned integer, not '%s'\n", a);
          return -1;
        }
        o->cfg.seed = (uint64_t)s;
        break;
      }
      case OPT_PERIOD:
      case OPT_DT:
      case OPT_NOISE:
      case OPT_LASER_X:
      case OPT_WATCHDOG:
        if (parse_double(a, &v) != 0) {
          fprintf(stderr, "b21r-sim: '%s' is not a number\n", a);
          return -1;
        }
        if (c == OPT_PERIOD) o->cfg.period_s = v;
        if (c == OPT_DT) o->cfg.plant.dt_s = v;
        if (c == OPT_NOISE) o->cfg.laser.noise_sigma_m = v;
        if (c == OPT_LASER_X) o->cfg.plant.laser_x_m = v;
        if (c == OPT_WATCHDOG) o->cfg.rflex.watchdog_s = v;
        break;
      case OPT_START:
        if (sscanf(a, "%lf,%lf,%lf", &o->start_x, &o->start_y, &o->start_th) != 3) {
          fprintf(stderr, "b21r-sim: --start needs X,Y,THETA (metres, radians), not '%s'\n", a);
          return -1;
        }
        o->have_start = 1;
        break;
      case OPT_START_INDEX:
        o->start_index = atoi(a);
        break;
      case OPT_BAUD:
        o->cfg.laser.power_up_baud = (uint32_t)strtoul(a, NULL, 10);
        break;
      case OPT_VARIANT: {
        unsigned w = 0;
        double r = 0.0;
        if (sscanf(a, "%u/%lf", &w, &r) != 2) {
          fprintf(stderr, "b21r-sim: --laser-variant needs WIDTH/RESOLUTION, e.g. 180/0.5\n");
          return -1;
        }
        o->cfg.laser.width_deg = (uint16_t)w;
        o->cfg.laser.res_cdeg = (uint16_t)lround(r * 100.0);
        break;
      }
      case OPT_UNIT:
        if (strcmp(a, "mm") != 0 && strcmp(a, "cm") != 0) {
          fprintf(stderr, "b21r-sim: --laser-unit must be mm or cm\n");
          return -1;
        }
        o->cfg.laser.unit_mm = strcmp(a, "mm") == 0 ? 1U : 0U;
        break;
      case OPT_BRAKE: o->cfg.rflex.brake_at_power_up = false; break;
      case OPT_HELP: usage(stdout); exit(0);
      default: usage(stderr); return -1;
    }
  }
  if (optind < argc) {
    fprintf(stderr, "b21r-sim: unexpected argument '%s'\n", argv[optind]);
    return -1;
  }
  if (o->world == NULL) {
    fprintf(stderr, "b21r-sim: --world FILE is required (try --help)\n");
    return -1;
  }
  if (o->can_log != NULL && o->cfg.base != SIM_BASE_CANOPEN) {
    fprintf(stderr, "b21r-sim: --can-log needs --base canopen (the rFLEX base has no CAN bus)\n");
    return -1;
  }
  if (o->can_log_iface == NULL) {
    o->can_log_iface = "vcan0";
  }
  return 0;
}

// ---- pending output --------------------------------------------------------------------------

static void pend_push(pend_t* p, const uint8_t* b, size_t n, uint64_t ready_ns) {
  if (n == 0) {
    return;
  }
  if (n > APP_PEND_BYTES - p->len || p->ch_len == APP_PEND_CHUNKS) {
    p->dropped += n;  // the reader is far behind: drop rather than grow without bound
    return;
  }
  for (size_t i = 0; i < n; ++i) {
    p->bytes[(p->head + p->len + i) % APP_PEND_BYTES] = b[i];
  }
  p->len += n;
  const size_t c = (p->ch_head + p->ch_len) % APP_PEND_CHUNKS;
  p->ch[c].ready_ns = ready_ns;
  p->ch[c].n = (uint32_t)n;
  ++p->ch_len;
}

// The next free slot of the frame queue, cleared and due at ready_ns; NULL (the frame counted as
// dropped) when the queue is full.
static struct can_frame* frame_pend_slot(frame_pend_t* p, uint64_t ready_ns) {
  if (p->len == APP_PEND_FRAMES) {
    ++p->dropped;
    return NULL;
  }
  const size_t i = (p->head + p->len) % APP_PEND_FRAMES;
  ++p->len;
  p->fr[i].ready_ns = ready_ns;
  memset(&p->fr[i].f, 0, sizeof(p->fr[i].f));
  return &p->fr[i].f;
}

static void pend_flush(pend_t* p, int fd, uint64_t now_ns) {
  while (p->ch_len > 0 && p->ch[p->ch_head].ready_ns <= now_ns) {
    const size_t n = p->ch[p->ch_head].n;
    const size_t contiguous = APP_PEND_BYTES - p->head < n ? APP_PEND_BYTES - p->head : n;
    const ssize_t k = write(fd, p->bytes + p->head, contiguous);
    if (k <= 0) {
      return;  // EAGAIN: the pty is full until the controller reads; retried on POLLOUT
    }
    p->head = (p->head + (size_t)k) % APP_PEND_BYTES;
    p->len -= (size_t)k;
    p->ch[p->ch_head].n -= (uint32_t)k;
    if (p->ch[p->ch_head].n == 0) {
      p->ch_head = (p->ch_head + 1U) % APP_PEND_CHUNKS;
      --p->ch_len;
    }
  }
}

static uint64_t pend_next_ns(const pend_t* p) {
  return p->ch_len > 0 ? p->ch[p->ch_head].ready_ns : UINT64_MAX;
}

// One line of the bus trace, as `candump -L` writes it: "(seconds.micros) iface ID#DATA", the
// time of day on the wall clock (so traces of sessions line up with other logs), the 11-bit ID
// in 3 hex digits. The file is flushed at most every 200 ms and at exit: cheap in lockstep,
// yet a `tail -f` follows it.
static void can_log_frame(app_t* a, const struct can_frame* f, uint64_t now_ns) {
  if (a->can_log == NULL) {
    return;
  }
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  char data[2 * CAN_MAX_DLEN + 1];
  const unsigned dlc = f->can_dlc <= CAN_MAX_DLEN ? f->can_dlc : CAN_MAX_DLEN;
  for (unsigned i = 0; i < dlc; ++i) {
    static const char hex[] = "0123456789ABCDEF";
    data[2 * i] = hex[f->data[i] >> 4];
    data[2 * i + 1] = hex[f->data[i] & 0x0F];
  }
  data[2 * dlc] = '\0';
  if ((f->can_id & CAN_ERR_FLAG) != 0U) {  // candump's form of an error frame
    fprintf(a->can_log, "(%lld.%06ld) %s %08X#%s\n", (long long)ts.tv_sec, ts.tv_nsec / 1000L, a->opt.can_log_iface,
            (unsigned)(f->can_id & (CAN_ERR_FLAG | CAN_ERR_MASK)), data);
  } else {
    fprintf(a->can_log, "(%lld.%06ld) %s %03X#%s\n", (long long)ts.tv_sec, ts.tv_nsec / 1000L, a->opt.can_log_iface,
            (unsigned)(f->can_id & CAN_SFF_MASK), data);
  }
  if (now_ns >= a->can_log_flush_ns) {
    fflush(a->can_log);
    a->can_log_flush_ns = now_ns + 200000000ULL;
  }
}

static void can_broadcast(app_t* a, const struct can_frame* f, int except_fd) {
  for (int i = 0; i < APP_MAX_CLIENTS; ++i) {
    const int fd = a->can_clients[i];
    if (fd < 0 || fd == except_fd) {
      continue;
    }
    if (send(fd, f, sizeof(*f), MSG_DONTWAIT | MSG_NOSIGNAL) != (ssize_t)sizeof(*f)) {
      ++a->can_out.dropped;
    }
  }
}

static void pump(app_t* a, uint64_t now_ns) {
  const uint64_t ready = now_ns + (uint64_t)llround(sim_emu_latency_s(a->emu) * 1e9);
  size_t n;
  while ((n = sim_emu_laser_read(a->emu, a->io, sizeof(a->io))) > 0) {
    pend_push(&a->laser_out, a->io, n, ready);
  }
  while ((n = sim_emu_base_read(a->emu, a->io, sizeof(a->io))) > 0) {
    pend_push(&a->base_out, a->io, n, ready);
  }
  canopen_frame_t f;
  while (sim_emu_can_read(a->emu, &f)) {
    struct can_frame* out = frame_pend_slot(&a->can_out, ready);
    if (out != NULL) {
      sim_can_to_linux(&f, out);
    }
  }
  // Failed CRCs on the bus reach the host as SocketCAN error frames (protocol violation in the
  // CRC sequence), as a CAN controller with error reporting on delivers them.
  for (uint32_t k = sim_emu_can_take_error_frames(a->emu); k > 0; --k) {
    struct can_frame* ef = frame_pend_slot(&a->can_out, ready);
    if (ef != NULL) {
      ef->can_id = CAN_ERR_FLAG | CAN_ERR_PROT;
      ef->can_dlc = CAN_ERR_DLC;
      ef->data[2] = CAN_ERR_PROT_BIT;
      ef->data[3] = CAN_ERR_PROT_LOC_CRC_SEQ;
    }
  }
  // The host's controller going bus-off and restarting, as SocketCAN reports both.
  for (sim_emu_bus_event_t ev = sim_emu_can_take_bus_event(a->emu); ev != SIM_EMU_BUS_NONE;
       ev = sim_emu_can_take_bus_event(a->emu)) {
    struct can_frame* ef = frame_pend_slot(&a->can_out, ready);
    if (ef != NULL) {
      ef->can_id = CAN_ERR_FLAG | (ev == SIM_EMU_BUS_OFF ? CAN_ERR_BUSOFF : CAN_ERR_RESTARTED);
      ef->can_dlc = CAN_ERR_DLC;
    }
  }
  pend_flush(&a->laser_out, a->laser_master, now_ns);
  if (a->base_master >= 0) {
    pend_flush(&a->base_out, a->base_master, now_ns);
  }
  while (a->can_out.len > 0 && a->can_out.fr[a->can_out.head].ready_ns <= now_ns) {
    can_log_frame(a, &a->can_out.fr[a->can_out.head].f, now_ns);
    can_broadcast(a, &a->can_out.fr[a->can_out.head].f, -1);
    a->can_out.head = (a->can_out.head + 1U) % APP_PEND_FRAMES;
    --a->can_out.len;
  }
}

// ---- set-up ----------------------------------------------------------------------------------

static int setup(app_t* a) {
  char err[512];
  if (sim_world_load(a->opt.world, &a->world, err, sizeof(err)) != SIM_WORLD_OK) {
    fprintf(stderr, "b21r-sim: %s\n", err);
    return -1;
  }
  a->emu = sim_emu_create(&a->world, &a->opt.cfg);
  if (a->emu == NULL) {
    fprintf(stderr,
            "b21r-sim: invalid configuration (period must be a multiple of dt; laser baud "
            "9600/19200/38400/500000; variant 180/1, 180/0.5, 100/1, 100/0.5 or 100/0.25)\n");
    return -1;
  }
  if (a->opt.have_start) {
    sim_emu_reset(a->emu, a->opt.start_x, a->opt.start_y, a->opt.start_th);
  } else if (a->opt.start_index >= 0) {
    if ((size_t)a->opt.start_index >= a->world.n_starts) {
      fprintf(stderr, "b21r-sim: the world has %zu start poses; --start-index %d is out of range\n",
              a->world.n_starts, a->opt.start_index);
      return -1;
    }
    const sim_pose_t* s = &a->world.starts[a->opt.start_index];
    sim_emu_reset(a->emu, s->x_m, s->y_m, s->theta_rad);
  }
  if (sim_pty_open(&a->laser_master, &a->laser_slave, a->laser_path, sizeof(a->laser_path)) != 0) {
    fprintf(stderr, "b21r-sim: cannot open a pseudo-terminal: %s\n", strerror(errno));
    return -1;
  }
  if (a->opt.cfg.base == SIM_BASE_RFLEX) {
    if (sim_pty_open(&a->base_master, &a->base_slave, a->base_path, sizeof(a->base_path)) != 0) {
      fprintf(stderr, "b21r-sim: cannot open a pseudo-terminal: %s\n", strerror(errno));
      return -1;
    }
  } else {
    if (a->opt.can != NULL) {
      (void)snprintf(a->can_path, sizeof(a->can_path), "%s", a->opt.can);
    } else if (a->opt.control != NULL) {
      (void)snprintf(a->can_path, sizeof(a->can_path), "%s.can", a->opt.control);
    } else {
      (void)snprintf(a->can_path, sizeof(a->can_path), "/tmp/b21r-sim-%ld.can", (long)getpid());
    }
    a->can_listen = sim_seqpacket_listen(a->can_path);
    if (a->can_listen < 0) {
      fprintf(stderr, "b21r-sim: cannot listen on %s: %s\n", a->can_path, strerror(errno));
      return -1;
    }
    if (a->opt.can_log != NULL && (a->can_log = fopen(a->opt.can_log, "w")) == NULL) {
      fprintf(stderr, "b21r-sim: cannot write %s: %s\n", a->opt.can_log, strerror(errno));
      return -1;
    }
  }
  if (a->opt.control != NULL) {
    a->ctl_listen = sim_seqpacket_listen(a->opt.control);
    if (a->ctl_listen < 0) {
      fprintf(stderr, "b21r-sim: cannot listen on %s: %s\n", a->opt.control, strerror(errno));
      return -1;
    }
  }
  sigset_t mask;
  sigemptyset(&mask);
  sigaddset(&mask, SIGINT);
  sigaddset(&mask, SIGTERM);
  sigaddset(&mask, SIGHUP);
  if (sigprocmask(SIG_BLOCK, &mask, NULL) != 0 ||
      (a->sig_fd = signalfd(-1, &mask, SFD_CLOEXEC | SFD_NONBLOCK)) < 0) {
    fprintf(stderr, "b21r-sim: cannot set up signal handling: %s\n", strerror(errno));
    return -1;
  }
  signal(SIGPIPE, SIG_IGN);
  char line[1024];
  int n = snprintf(line, sizeof(line), "laser=%s", a->laser_path);
  if (a->base_master >= 0) {
    n += snprintf(line + n, sizeof(line) - (size_t)n, " base=%s", a->base_path);
  }
  if (a->can_listen >= 0) {
    n += snprintf(line + n, sizeof(line) - (size_t)n, " can=%s", a->can_path);
  }
  if (a->ctl_listen >= 0) {
    n += snprintf(line + n, sizeof(line) - (size_t)n, " control=%s", a->opt.control);
  }
  (void)snprintf(line + n, sizeof(line) - (size_t)n, "\n");
  if (a->opt.endpoints != NULL && sim_write_file_atomic(a->opt.endpoints, line) != 0) {
    fprintf(stderr, "b21r-sim: cannot write %s: %s\n", a->opt.endpoints, strerror(errno));
    return -1;
  }
  fputs(line, stdout);
  fflush(stdout);
  return 0;
}

static void add_client(int listen_fd, int* clients) {
  const int fd = accept4(listen_fd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
  if (fd < 0) {
    return;
  }
  for (int i = 0; i < APP_MAX_CLIENTS; ++i) {
    if (clients[i] < 0) {
      clients[i] = fd;
      return;
    }
  }
  close(fd);  // bus full
}

static void serve_control(app_t* a, int slot) {
  char line[1024];
  const ssize_t n = recv(a->ctl_clients[slot], line, sizeof(line) - 1, 0);
  if (n <= 0) {
    if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
      close(a->ctl_clients[slot]);
      a->ctl_clients[slot] = -1;
    }
    return;
  }
  line[n] = '\0';
  char reply[1024];
  const sim_emu_ctrl_t rc = sim_emu_control(a->emu, line, reply, sizeof(reply));
  (void)send(a->ctl_clients[slot], reply, strlen(reply), MSG_NOSIGNAL);
  if (rc == SIM_EMU_CTRL_QUIT) {
    a->quit = 1;
  }
}

static void serve_can(app_t* a, int slot) {
  for (;;) {
    struct can_frame f;
    const ssize_t n = recv(a->can_clients[slot], &f, sizeof(f), 0);
    if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
      return;
    }
    if (n <= 0) {
      close(a->can_clients[slot]);
      a->can_clients[slot] = -1;
      return;
    }
    if ((size_t)n < offsetof(struct can_frame, data) ||
        (f.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0) {
      continue;  // not a classic data frame: not for the emulated drives
    }
    canopen_frame_t cf;
    sim_can_from_linux(&f, &cf);
    can_log_frame(a, &f, mono_ns());
    can_broadcast(a, &f, a->can_clients[slot]);  // the other nodes on the bus see it too
    sim_emu_can_write(a->emu, &cf);
    pump(a, mono_ns());  // keep the drives' answers in bus order
  }
}

static void serve_serial(app_t* a, int fd, int laser) {
  for (;;) {
    const ssize_t n = read(fd, a->io, sizeof(a->io));
    if (n <= 0) {
      return;
    }
    if (laser) {
      sim_emu_laser_write(a->emu, a->io, (size_t)n);
    } else {
      sim_emu_base_write(a->emu, a->io, (size_t)n);
    }
  }
}

static int run(app_t* a) {
  a->t0_ns = mono_ns();
  const int realtime = a->opt.cfg.mode == SIM_MODE_REALTIME;
  while (!a->quit) {
    uint64_t now = mono_ns();
    if (realtime) {
      sim_emu_run_until(a->emu, (double)(now - a->t0_ns) * 1e-9);
    }
    pump(a, now);
    struct pollfd pfd[4 + 2 * APP_MAX_CLIENTS];
    int kinds[4 + 2 * APP_MAX_CLIENTS];  // 0 signal 1 laser 2 base 3 can-listen 4 ctl-listen 5+i can 20+i ctl
    nfds_t n = 0;
    pfd[n] = (struct pollfd){a->sig_fd, POLLIN, 0};
    kinds[n++] = 0;
    // POLLOUT only for output that is due and waits for room: output held back by the latency
    // fault is not due yet, and a pty is nearly always writable (poll would return at once).
    const short laser_out = pend_next_ns(&a->laser_out) <= now ? POLLOUT : 0;
    const short base_out = pend_next_ns(&a->base_out) <= now ? POLLOUT : 0;
    pfd[n] = (struct pollfd){a->laser_master, (short)(POLLIN | laser_out), 0};
    kinds[n++] = 1;
    if (a->base_master >= 0) {
      pfd[n] = (struct pollfd){a->base_master, (short)(POLLIN | base_out), 0};
      kinds[n++] = 2;
    }
    if (a->can_listen >= 0) {
      pfd[n] = (struct pollfd){a->can_listen, POLLIN, 0};
      kinds[n++] = 3;
    }
    if (a->ctl_listen >= 0) {
      pfd[n] = (struct pollfd){a->ctl_listen, POLLIN, 0};
      kinds[n++] = 4;
    }
    for (int i = 0; i < APP_MAX_CLIENTS; ++i) {
      if (a->can_clients[i] >= 0) {
        pfd[n] = (struct pollfd){a->can_clients[i], POLLIN, 0};
        kinds[n++] = 5 + i;
      }
      if (a->ctl_clients[i] >= 0) {
        pfd[n] = (struct pollfd){a->ctl_clients[i], POLLIN, 0};
        kinds[n++] = 20 + i;
      }
    }
    // Wake for the next delayed output; in real time at least every millisecond.
    uint64_t next = pend_next_ns(&a->laser_out);
    const uint64_t nb = pend_next_ns(&a->base_out);
    next = nb < next ? nb : next;
    if (a->can_out.len > 0 && a->can_out.fr[a->can_out.head].ready_ns < next) {
      next = a->can_out.fr[a->can_out.head].ready_ns;
    }
    int timeout_ms = -1;
    if (next != UINT64_MAX) {
      timeout_ms = next <= now ? 1 : (int)((next - now) / 1000000ULL) + 1;  // POLLOUT may be pending
    }
    if (realtime) {
      timeout_ms = 1;
    }
    const int rc = poll(pfd, n, timeout_ms);
    if (rc < 0) {
      if (errno == EINTR) {
        continue;
      }
      fprintf(stderr, "b21r-sim: poll: %s\n", strerror(errno));
      return -1;
    }
    now = mono_ns();
    if (realtime) {
      sim_emu_run_until(a->emu, (double)(now - a->t0_ns) * 1e-9);
    }
    for (nfds_t i = 0; i < n; ++i) {
      if (pfd[i].revents == 0) {
        continue;
      }
      const int k = kinds[i];
      if (k == 0) {
        a->quit = 1;
      } else if (k == 1 && (pfd[i].revents & POLLIN)) {
        serve_serial(a, a->laser_master, 1);
      } else if (k == 2 && (pfd[i].revents & POLLIN)) {
        serve_serial(a, a->base_master, 0);
      } else if (k == 3) {
        add_client(a->can_listen, a->can_clients);
      } else if (k == 4) {
        add_client(a->ctl_listen, a->ctl_clients);
      } else if (k >= 5 && k < 5 + APP_MAX_CLIENTS && a->can_clients[k - 5] >= 0) {
        serve_can(a, k - 5);
      } else if (k >= 20 && a->ctl_clients[k - 20] >= 0) {
        serve_control(a, k - 20);
      }
    }
    pump(a, mono_ns());
  }
  return 0;
}

static void teardown(app_t* a) {
  if (a->opt.trace_svg != NULL && a->emu != NULL && sim_emu_write_svg(a->emu, a->opt.trace_svg) != 0) {
    fprintf(stderr, "b21r-sim: cannot write %s: %s\n", a->opt.trace_svg, strerror(errno));
  }
  const int fds[] = {a->laser_master, a->laser_slave, a->base_master, a->base_slave,
                     a->can_listen,   a->ctl_listen,  a->sig_fd};
  for (size_t i = 0; i < sizeof(fds) / sizeof(fds[0]); ++i) {
    if (fds[i] >= 0) {
      close(fds[i]);
    }
  }
  for (int i = 0; i < APP_MAX_CLIENTS; ++i) {
    if (a->can_clients[i] >= 0) close(a->can_clients[i]);
    if (a->ctl_clients[i] >= 0) close(a->ctl_clients[i]);
  }
  if (a->can_listen >= 0) unlink(a->can_path);
  if (a->ctl_listen >= 0) unlink(a->opt.control);
  if (a->can_log != NULL && fclose(a->can_log) != 0) {
    fprintf(stderr, "b21r-sim: cannot write %s: %s\n", a->opt.can_log, strerror(errno));
  }
  sim_emu_destroy(a->emu);
}

int main(int argc, char** argv) {
  app_t* a = calloc(1, sizeof(*a));
  if (a == NULL) {
    fprintf(stderr, "b21r-sim: out of memory\n");
    return 1;
  }
  a->laser_master = a->laser_slave = a->base_master = a->base_slave = -1;
  a->can_listen = a->ctl_listen = a->sig_fd = -1;
  for (int i = 0; i < APP_MAX_CLIENTS; ++i) {
    a->can_clients[i] = a->ctl_clients[i] = -1;
  }
  int rc = 2;
  if (parse_args(argc, argv, &a->opt) == 0) {
    rc = setup(a) == 0 && run(a) == 0 ? 0 : 1;
  }
  teardown(a);
  free(a);
  return rc;
}
