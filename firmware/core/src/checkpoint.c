// SPDX-License-Identifier: MIT
// Checkpoint files (write temp, fsync, rename, fsync directory) and the background writer.
#define _POSIX_C_SOURCE 200809L
#include "fw/checkpoint.h"

#include "fw/prefault.h"
#include "pi_mutex.h"
#include "le_bytes.h"
#include "fw/errfmt.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static const char k_magic[8] = {'B', '2', '1', 'R', 'C', 'K', 'P', 'T'};

uint32_t fw_crc32(uint32_t crc, const void* data, size_t n) {
  // Nibble table: small and fast enough for checkpoints written off the tick.
  static const uint32_t table[16] = {0x00000000U, 0x1DB71064U, 0x3B6E20C8U, 0x26D930ACU, 0x76DC4190U, 0x6B6B51F4U,
                                     0x4DB26158U, 0x5005713CU, 0xEDB88320U, 0xF00F9344U, 0xD6D6A3E8U, 0xCB61B38CU,
                                     0x9B64C2B0U, 0x86D3D2D4U, 0xA00AE278U, 0xBDBDF21CU};
  const uint8_t* p = (const uint8_t*)data;
  crc = ~crc;
  for (size_t i = 0; i < n; ++i) {
    crc ^= p[i];
    crc = (crc >> 4) ^ table[crc & 0x0FU];
    crc = (crc >> 4) ^ table[crc & 0x0FU];
  }
  return ~crc;
}





static int write_all(int fd, const void* data, size_t n) {
  const uint8_t* p = (const uint8_t*)data;
  while (n > 0) {
    const ssize_t w = write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) {
        continue;
      }
      return -1;
    }
    p += w;
    n -= (size_t)w;
  }
  return 0;
}

static int fsync_dir_of(const char* path) {
  char dir[4096];
  const char* slash = strrchr(path, '/');
  if (slash == NULL) {
    strcpy(dir, ".");
  } else if (slash == path) {
    strcpy(dir, "/");
  } else {
    const size_t n = (size_t)(slash - path);
    if (n >= sizeof dir) {
      errno = ENAMETOOLONG;
      return -1;
    }
    memcpy(dir, path, n);
    dir[n] = '\0';
  }
  const int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    return -1;
  }
  const int r = fsync(fd);
  close(fd);
  return r;
}

int fw_checkpoint_write(const char* path, const void* meta, size_t meta_size, const void* payload,
                        size_t payload_size, char* err, size_t err_cap) {
  char tmp[4096];
  if ((size_t)snprintf(tmp, sizeof tmp, "%s.tmp", path) >= sizeof tmp) {
    fw_errfmt(err, err_cap, "checkpoint %s: path too long", path);
    return -1;
  }
  uint8_t header[FW_CHECKPOINT_HEADER_SIZE];
  memset(header, 0, sizeof header);
  memcpy(header, k_magic, sizeof k_magic);
  fw_put_u32(header + 8, FW_CHECKPOINT_VERSION);
  fw_put_u32(header + 12, FW_CHECKPOINT_HEADER_SIZE);
  fw_put_u64(header + 16, (uint64_t)meta_size);
  fw_put_u64(header + 24, (uint64_t)payload_size);
  fw_put_u32(header + 32, fw_crc32(0, meta, meta_size));
  fw_put_u32(header + 36, fw_crc32(0, payload, payload_size));
  fw_put_u32(header + 44, fw_crc32(0, header, 44));

  const int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    fw_errfmt(err, err_cap, "checkpoint: cannot create %s: %s", tmp, strerror(errno));
    return -1;
  }
  const char* step = NULL;
  if (write_all(fd, header, sizeof header) != 0 || write_all(fd, meta, meta_size) != 0 ||
      write_all(fd, payload, payload_size) != 0) {
    step = "write";
  } else if (fsync(fd) != 0) {
    step = "fsync";
  }
  const int saved = errno;
  if (close(fd) != 0 && step == NULL) {
    step = "close";
  }
  if (step != NULL) {
    fw_errfmt(err, err_cap, "checkpoint: %s of %s failed: %s (previous checkpoint %s kept)", step, tmp,
        strerror(step[0] == 'c' ? errno : saved), path);
    unlink(tmp);
    return -1;
  }
  if (rename(tmp, path) != 0) {
    fw_errfmt(err, err_cap, "checkpoint: rename %s -> %s failed: %s (previous checkpoint kept)", tmp, path,
        strerror(errno));
    unlink(tmp);
    return -1;
  }
  if (fsync_dir_of(path) != 0) {
    // The new file is in place; only its durability across power loss is in doubt.
    fw_errfmt(err, err_cap, "checkpoint: fsync of the directory of %s failed: %s", path, strerror(errno));
    return -1;
  }
  return 0;
}

// Opens path for reading: 1 (open, *out set), 0 (no such file), -1 (err says why). A directory
// or another non-regular file is refused by name (reading a directory would look like a
// truncated file); O_NONBLOCK keeps the open of a FIFO from waiting for a writer.
static int open_checkpoint(const char* path, FILE** out, char* err, size_t err_cap) {
  const int fd = open(path, O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    if (errno == ENOENT) {
      return 0;
    }
    fw_errfmt(err, err_cap, "checkpoint %s: cannot open: %s", path, strerror(errno));
    return -1;
  }
  struct stat st;
  const char* problem = NULL;
  if (fstat(fd, &st) != 0) {
    fw_errfmt(err, err_cap, "checkpoint %s: cannot stat: %s", path, strerror(errno));
    problem = "stat";
  } else if (S_ISDIR(st.st_mode)) {
    fw_errfmt(err, err_cap,
        "checkpoint %s is a directory; checkpoint_file must name a file (e.g. '%s/hedger.ckpt'), which is created "
        "if it does not exist",
        path, path);
    problem = "directory";
  } else if (!S_ISREG(st.st_mode)) {
    fw_errfmt(err, err_cap, "checkpoint %s is not a regular file; checkpoint_file must name a file", path);
    problem = "type";
  }
  FILE* f = problem == NULL ? fdopen(fd, "rb") : NULL;
  if (f == NULL) {
    if (problem == NULL) {
      fw_errfmt(err, err_cap, "checkpoint %s: cannot open: %s", path, strerror(errno));
    }
    close(fd);
    return -1;
  }
  *out = f;
  return 1;
}

// "truncated" for a short file, the system's reason for a failed read.
static void short_read(FILE* f, const char* path, const char* what, char* err, size_t err_cap) {
  if (ferror(f)) {
    fw_errfmt(err, err_cap, "checkpoint %s: cannot read: %s", path, strerror(errno));
  } else {
    fw_errfmt(err, err_cap, "checkpoint %s is truncated (%s); " FW_CHECKPOINT_FRESH_HINT, path, what, path, path);
  }
}

static int read_header(FILE* f, const char* path, uint64_t* meta_size, uint64_t* payload_size, uint32_t* meta_crc,
                       uint32_t* payload_crc, char* err, size_t err_cap) {
  uint8_t h[FW_CHECKPOINT_HEADER_SIZE];
  if (fread(h, 1, sizeof h, f) != sizeof h) {
    short_read(f, path, "shorter than its header", err, err_cap);
    return -1;
  }
  if (memcmp(h, k_magic, sizeof k_magic) != 0) {
    fw_errfmt(err, err_cap, "%s is not a B21r checkpoint (bad magic); " FW_CHECKPOINT_FRESH_HINT, path, path, path);
    return -1;
  }
  if (fw_get_u32(h + 44) != fw_crc32(0, h, 44)) {
    fw_errfmt(err, err_cap, "checkpoint %s is corrupt (header checksum mismatch); " FW_CHECKPOINT_FRESH_HINT,
        path, path, path);
    return -1;
  }
  const uint32_t version = fw_get_u32(h + 8);
  if (version != FW_CHECKPOINT_VERSION || fw_get_u32(h + 12) != FW_CHECKPOINT_HEADER_SIZE) {
    fw_errfmt(err, err_cap,
        "checkpoint %s has format version %u; this controller reads version %u only; " FW_CHECKPOINT_FRESH_HINT, path,
        (unsigned)version, FW_CHECKPOINT_VERSION, path, path);
    return -1;
  }
  *meta_size = fw_get_u64(h + 16);
  *payload_size = fw_get_u64(h + 24);
  *meta_crc = fw_get_u32(h + 32);
  *payload_crc = fw_get_u32(h + 36);
  return 0;
}

int fw_checkpoint_peek(const char* path, size_t* meta_size, size_t* payload_size, char* err, size_t err_cap) {
  FILE* f = NULL;
  const int o = open_checkpoint(path, &f, err, err_cap);
  if (o <= 0) {
    return o;
  }
  uint64_t m = 0;
  uint64_t p = 0;
  uint32_t mc = 0;
  uint32_t pc = 0;
  const int r = read_header(f, path, &m, &p, &mc, &pc, err, err_cap);
  fclose(f);
  if (r != 0) {
    return -1;
  }
  if (m > SIZE_MAX / 2 || p > SIZE_MAX / 2) {
    fw_errfmt(err, err_cap, "checkpoint %s is corrupt (implausible section sizes); " FW_CHECKPOINT_FRESH_HINT,
        path, path, path);
    return -1;
  }
  *meta_size = (size_t)m;
  *payload_size = (size_t)p;
  return 1;
}

int fw_checkpoint_read(const char* path, void* meta, size_t meta_cap, size_t* meta_size, void* payload,
                       size_t payload_cap, size_t* payload_size, char* err, size_t err_cap) {
  FILE* f = NULL;
  const int o = open_checkpoint(path, &f, err, err_cap);
  if (o <= 0) {
    return o;
  }
  uint64_t m = 0;
  uint64_t p = 0;
  uint32_t mc = 0;
  uint32_t pc = 0;
  int rc = read_header(f, path, &m, &p, &mc, &pc, err, err_cap);
  if (rc == 0 && (m > meta_cap || p > payload_cap)) {
    fw_errfmt(err, err_cap,
        "checkpoint %s holds %llu + %llu bytes, more than this configuration can load (%zu + %zu; "
        "was it written with a larger hedger_capacity?); " FW_CHECKPOINT_FRESH_HINT,
        path, (unsigned long long)m, (unsigned long long)p, meta_cap, payload_cap, path, path);
    rc = -1;
  }
  if (rc == 0 && (fread(meta, 1, (size_t)m, f) != (size_t)m || fread(payload, 1, (size_t)p, f) != (size_t)p)) {
    short_read(f, path, "sections shorter than the header says", err, err_cap);
    rc = -1;
  }
  if (rc == 0 && fgetc(f) != EOF) {
    fw_errfmt(err, err_cap, "checkpoint %s has trailing bytes after its sections; " FW_CHECKPOINT_FRESH_HINT,
        path, path, path);
    rc = -1;
  }
  if (rc == 0 && (fw_crc32(0, meta, (size_t)m) != mc || fw_crc32(0, payload, (size_t)p) != pc)) {
    fw_errfmt(err, err_cap, "checkpoint %s is corrupt (section checksum mismatch); " FW_CHECKPOINT_FRESH_HINT,
        path, path, path);
    rc = -1;
  }
  fclose(f);
  if (rc != 0) {
    return -1;
  }
  *meta_size = (size_t)m;
  *payload_size = (size_t)p;
  return 1;
}

// ---- background writer -------------------------------------------------------------------

enum { BUF_FREE = 0, BUF_FILLING, BUF_PENDING, BUF_WRITING };

// A journal record waiting to be appended.
typedef struct journal_slot {
  uint8_t* buf;
  size_t size;
  int32_t run_id;
  int state;          // BUF_FREE, BUF_PENDING, BUF_WRITING
  uint64_t order;
} journal_slot_t;

#define JOURNAL_SLOTS_MAX 16U

struct fw_ckpt_writer {
  char path[4096];
  char journal_path[4096 + 16];
  size_t meta_cap;
  size_t payload_cap;
  uint8_t* buf[2];
  size_t meta_size[2];
  size_t payload_size[2];
  int32_t covered_run[2]; // the run whose state the buffer holds (-1: none or unknown)
  int state[2];
  uint64_t order[2];      // submission order: the oldest pending is written first
  uint64_t next_order;
  bool stop;
  fw_ckpt_counters_t counters;
  // The journal (writer thread: jfd, appended_run, broken; under mu: the slots).
  journal_slot_t jslot[JOURNAL_SLOTS_MAX];
  uint32_t jslots;
  size_t jrecord_cap;
  int jfd;
  int32_t appended_run;   // the last run appended in an unbroken sequence since the covering checkpoint
  bool broken;            // an append failed or a record was skipped: no more until a checkpoint
  _Atomic int32_t durable_run;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  pthread_t thread;
};

// The next job in submission order: a checkpoint buffer (0, 1) or a journal slot (2 + i); -1.
static int pick_pending(const fw_ckpt_writer_t* w) {
  int best = -1;
  uint64_t best_order = UINT64_MAX;
  for (int i = 0; i < 2; ++i) {
    if (w->state[i] == BUF_PENDING && w->order[i] < best_order) {
      best = i;
      best_order = w->order[i];
    }
  }
  for (uint32_t i = 0; i < w->jslots; ++i) {
    if (w->jslot[i].state == BUF_PENDING && w->jslot[i].order < best_order) {
      best = 2 + (int)i;
      best_order = w->jslot[i].order;
    }
  }
  return best;
}

static void raise_durable(fw_ckpt_writer_t* w, int32_t run) {
  if (run > atomic_load(&w->durable_run)) {
    atomic_store(&w->durable_run, run);
  }
}

// Appends one record and syncs it (the writer's thread, no lock held). 0, or -1 with err.
static int journal_append(fw_ckpt_writer_t* w, const uint8_t* rec, size_t n, char* err, size_t err_cap) {
  if (w->jfd < 0) {
    fw_errfmt(err, err_cap, "journal %s is not open", w->journal_path);
    return -1;
  }
  if (write_all(w->jfd, rec, n) != 0 || fdatasync(w->jfd) != 0) {
    fw_errfmt(err, err_cap, "journal: appending to %s failed: %s (the runs since the last checkpoint are kept "
              "only in memory until the next one)", w->journal_path, strerror(errno));
    return -1;
  }
  return 0;
}

// A checkpoint that covers every journalled run is on disk: the journal starts empty again.
static void journal_reset(fw_ckpt_writer_t* w) {
  if (w->jfd >= 0 && (ftruncate(w->jfd, 0) != 0 || fdatasync(w->jfd) != 0)) {
    fprintf(stderr, "b21r-controller: journal: emptying %s failed: %s (its runs are in the checkpoint)\n",
            w->journal_path, strerror(errno));
  }
}

static void* writer_main(void* arg) {
  fw_ckpt_writer_t* w = (fw_ckpt_writer_t*)arg;
  pthread_mutex_lock(&w->mu);
  for (;;) {
    int i = pick_pending(w);
    while (i < 0 && !w->stop) {
      pthread_cond_wait(&w->cv, &w->mu);
      i = pick_pending(w);
    }
    if (i < 0) {
      break;
    }
    char err[FW_CHECKPOINT_ERR_MAX];
    if (i >= 2) {
      journal_slot_t* j = &w->jslot[i - 2];
      j->state = BUF_WRITING;
      const bool skip = w->broken || j->run_id != w->appended_run + 1;
      pthread_mutex_unlock(&w->mu);
      // A record that does not follow the last one without a gap cannot be replayed after it:
      // it waits for a checkpoint like a run without a journal.
      const int r = skip ? 1 : journal_append(w, j->buf, j->size, err, sizeof err);
      if (r < 0) {
        fprintf(stderr, "b21r-controller: %s\n", err);
      }
      pthread_mutex_lock(&w->mu);
      if (r == 0) {
        w->counters.journal_written++;
        w->appended_run = j->run_id;
        raise_durable(w, j->run_id);
      } else {
        w->broken = true;
        if (r < 0) {
          w->counters.journal_failed++;
        } else {
          w->counters.journal_skipped++;
        }
      }
      j->state = BUF_FREE;
      pthread_cond_broadcast(&w->cv);
      continue;
    }
    w->state[i] = BUF_WRITING;
    const int32_t covered = w->covered_run[i];
    // Every journalled run is in it unless a later run's record went first (never expected: a run
    // starts after the checkpoint of the one before is submitted).
    const bool covers_journal = covered >= 0 && covered >= w->appended_run;
    pthread_mutex_unlock(&w->mu);
    const int r = fw_checkpoint_write(w->path, w->buf[i], w->meta_size[i], w->buf[i] + w->meta_cap,
                                      w->payload_size[i], err, sizeof err);
    if (r != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
    } else if (covers_journal) {
      journal_reset(w);
    }
    pthread_mutex_lock(&w->mu);
    if (r == 0) {
      w->counters.written++;
      if (covers_journal) {
        w->appended_run = covered;
        w->broken = false;
      }
      if (covered >= 0) {
        raise_durable(w, covered);
      }
    } else {
      w->counters.failed++;
    }
    w->state[i] = BUF_FREE;
    pthread_cond_broadcast(&w->cv);
  }
  pthread_mutex_unlock(&w->mu);
  return NULL;
}

fw_ckpt_writer_t* fw_ckpt_writer_create(const char* path, size_t meta_cap, size_t payload_cap, char* err,
                                        size_t err_cap) {
  fw_ckpt_writer_t* w = (fw_ckpt_writer_t*)calloc(1, sizeof *w);
  if (w == NULL) {
    fw_errfmt(err, err_cap, "checkpoint writer: out of memory");
    return NULL;
  }
  if (strlen(path) + 8 >= sizeof w->path) {
    fw_errfmt(err, err_cap, "checkpoint writer: path too long: %s", path);
    free(w);
    return NULL;
  }
  strcpy(w->path, path);
  snprintf(w->journal_path, sizeof w->journal_path, "%s.journal", path);
  w->jfd = -1;
  w->appended_run = -1;
  atomic_init(&w->durable_run, -1);
  w->covered_run[0] = -1;
  w->covered_run[1] = -1;
  w->meta_cap = meta_cap;
  w->payload_cap = payload_cap;
  for (int i = 0; i < 2; ++i) {
    w->buf[i] = (uint8_t*)malloc(meta_cap + payload_cap + 1U);
    if (w->buf[i] == NULL) {
      fw_errfmt(err, err_cap, "checkpoint writer: cannot allocate %zu bytes", meta_cap + payload_cap);
      free(w->buf[0]);
      free(w);
      return NULL;
    }
  }
  fw_pi_mutex_init(&w->mu);  // the tick reads the counters and acquires buffers
  pthread_cond_init(&w->cv, NULL);
  if (pthread_create(&w->thread, NULL, writer_main, w) != 0) {
    fw_errfmt(err, err_cap, "checkpoint writer: cannot start thread");
    pthread_mutex_destroy(&w->mu);
    pthread_cond_destroy(&w->cv);
    free(w->buf[0]);
    free(w->buf[1]);
    free(w);
    return NULL;
  }
  return w;
}

int fw_ckpt_writer_acquire(fw_ckpt_writer_t* w, void** meta, size_t* meta_cap, void** payload,
                           size_t* payload_cap) {
  pthread_mutex_lock(&w->mu);
  int pick = -1;
  for (int i = 0; i < 2 && pick < 0; ++i) {
    if (w->state[i] == BUF_FREE) {
      pick = i;
    }
  }
  if (pick < 0) {
    // Both busy: take over a pending buffer that the thread has not started; the new state wins.
    for (int i = 0; i < 2 && pick < 0; ++i) {
      if (w->state[i] == BUF_PENDING) {
        pick = i;
        w->counters.superseded++;
      }
    }
  }
  if (pick < 0) {
    w->counters.busy++;
    pthread_mutex_unlock(&w->mu);
    return -1;
  }
  w->state[pick] = BUF_FILLING;
  pthread_mutex_unlock(&w->mu);
  *meta = w->buf[pick];
  *meta_cap = w->meta_cap;
  *payload = w->buf[pick] + w->meta_cap;
  *payload_cap = w->payload_cap;
  return pick;
}

void fw_ckpt_writer_submit(fw_ckpt_writer_t* w, int handle, size_t meta_size, size_t payload_size) {
  fw_ckpt_writer_submit_run(w, handle, meta_size, payload_size, -1);
}

void fw_ckpt_writer_submit_run(fw_ckpt_writer_t* w, int handle, size_t meta_size, size_t payload_size,
                               int32_t covered_run) {
  if (handle < 0 || handle > 1) {
    return;
  }
  pthread_mutex_lock(&w->mu);
  w->covered_run[handle] = covered_run;
  // An older pending checkpoint is superseded by this newer one.
  const int other = 1 - handle;
  if (w->state[other] == BUF_PENDING) {
    w->state[other] = BUF_FREE;
    w->counters.superseded++;
  }
  w->meta_size[handle] = meta_size;
  w->payload_size[handle] = payload_size;
  w->state[handle] = BUF_PENDING;
  w->order[handle] = w->next_order++;
  pthread_cond_broadcast(&w->cv);
  pthread_mutex_unlock(&w->mu);
}

static bool writer_busy(const fw_ckpt_writer_t* w) {
  for (int i = 0; i < 2; ++i) {
    if (w->state[i] == BUF_PENDING || w->state[i] == BUF_WRITING) {
      return true;
    }
  }
  for (uint32_t i = 0; i < w->jslots; ++i) {
    if (w->jslot[i].state != BUF_FREE) {
      return true;
    }
  }
  return false;
}

void fw_ckpt_writer_flush(fw_ckpt_writer_t* w) {
  pthread_mutex_lock(&w->mu);
  while (writer_busy(w)) {
    pthread_cond_wait(&w->cv, &w->mu);
  }
  pthread_mutex_unlock(&w->mu);
}

int fw_ckpt_writer_journal_init(fw_ckpt_writer_t* w, size_t record_cap, uint32_t slots, int32_t durable_run,
                                size_t keep_bytes, char* err, size_t err_cap) {
  if (w->jslots > 0U || slots == 0U || slots > JOURNAL_SLOTS_MAX || record_cap == 0U) {
    fw_errfmt(err, err_cap, "journal %s: invalid set-up", w->journal_path);
    return -1;
  }
  for (uint32_t i = 0; i < slots; ++i) {
    w->jslot[i].buf = (uint8_t*)malloc(record_cap);
    if (w->jslot[i].buf == NULL) {
      fw_errfmt(err, err_cap, "journal: cannot allocate %zu bytes", record_cap);
      for (uint32_t k = 0; k < i; ++k) {
        free(w->jslot[k].buf);
        w->jslot[k].buf = NULL;
      }
      return -1;
    }
  }
  const int fd = open(w->journal_path, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0 || ftruncate(fd, (off_t)keep_bytes) != 0 || fsync(fd) != 0 || fsync_dir_of(w->journal_path) != 0) {
    fw_errfmt(err, err_cap, "journal: cannot create %s: %s (it lies beside checkpoint_file, which must be in a "
              "writable directory)", w->journal_path, strerror(errno));
    if (fd >= 0) {
      close(fd);
    }
    for (uint32_t k = 0; k < slots; ++k) {
      free(w->jslot[k].buf);
      w->jslot[k].buf = NULL;
    }
    return -1;
  }
  pthread_mutex_lock(&w->mu);
  w->jfd = fd;
  w->jslots = slots;
  w->jrecord_cap = record_cap;
  w->appended_run = durable_run;
  atomic_store(&w->durable_run, durable_run);
  pthread_mutex_unlock(&w->mu);
  return 0;
}

int fw_ckpt_writer_journal_submit(fw_ckpt_writer_t* w, const void* record, size_t n, int32_t run_id) {
  pthread_mutex_lock(&w->mu);
  journal_slot_t* j = NULL;
  for (uint32_t i = 0; i < w->jslots && j == NULL; ++i) {
    if (w->jslot[i].state == BUF_FREE) {
      j = &w->jslot[i];
    }
  }
  if (j == NULL || n > w->jrecord_cap) {
    // Not journalled: the records after it no longer follow without a gap either.
    w->counters.journal_skipped++;
    w->broken = w->jslots > 0U;
    pthread_mutex_unlock(&w->mu);
    return -1;
  }
  j->state = BUF_WRITING;  // the copy below is ours; the thread does not look at it meanwhile
  pthread_mutex_unlock(&w->mu);
  memcpy(j->buf, record, n);
  pthread_mutex_lock(&w->mu);
  j->size = n;
  j->run_id = run_id;
  j->order = w->next_order++;
  j->state = BUF_PENDING;
  pthread_cond_broadcast(&w->cv);
  pthread_mutex_unlock(&w->mu);
  return 0;
}

int32_t fw_ckpt_writer_durable_run(fw_ckpt_writer_t* w) { return atomic_load(&w->durable_run); }

fw_ckpt_counters_t fw_ckpt_writer_counters(fw_ckpt_writer_t* w) {
  pthread_mutex_lock(&w->mu);
  const fw_ckpt_counters_t c = w->counters;
  pthread_mutex_unlock(&w->mu);
  return c;
}

void fw_ckpt_writer_prefault(fw_ckpt_writer_t* w) {
  for (int i = 0; i < 2; ++i) {
    fw_prefault(w->buf[i], w->meta_cap + w->payload_cap + 1U);
  }
  for (uint32_t i = 0; i < w->jslots; ++i) {
    fw_prefault(w->jslot[i].buf, w->jrecord_cap);
  }
}

void fw_ckpt_writer_destroy(fw_ckpt_writer_t* w) {
  if (w == NULL) {
    return;
  }
  fw_ckpt_writer_flush(w);
  pthread_mutex_lock(&w->mu);
  w->stop = true;
  pthread_cond_broadcast(&w->cv);
  pthread_mutex_unlock(&w->mu);
  pthread_join(w->thread, NULL);
  pthread_mutex_destroy(&w->mu);
  pthread_cond_destroy(&w->cv);
  if (w->jfd >= 0) {
    close(w->jfd);
  }
  for (uint32_t i = 0; i < w->jslots; ++i) {
    free(w->jslot[i].buf);
  }
  free(w->buf[0]);
  free(w->buf[1]);
  free(w);
}
