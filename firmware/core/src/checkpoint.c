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

struct fw_ckpt_writer {
  char path[4096];
  size_t meta_cap;
  size_t payload_cap;
  uint8_t* buf[2];
  size_t meta_size[2];
  size_t payload_size[2];
  int state[2];
  uint64_t order[2];      // submission order: the oldest pending is written first
  uint64_t next_order;
  bool stop;
  fw_ckpt_counters_t counters;
  pthread_mutex_t mu;
  pthread_cond_t cv;
  pthread_t thread;
};

static int pick_pending(const fw_ckpt_writer_t* w) {
  int best = -1;
  for (int i = 0; i < 2; ++i) {
    if (w->state[i] == BUF_PENDING && (best < 0 || w->order[i] < w->order[best])) {
      best = i;
    }
  }
  return best;
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
    w->state[i] = BUF_WRITING;
    pthread_mutex_unlock(&w->mu);
    char err[FW_CHECKPOINT_ERR_MAX];
    const int r = fw_checkpoint_write(w->path, w->buf[i], w->meta_size[i], w->buf[i] + w->meta_cap,
                                      w->payload_size[i], err, sizeof err);
    if (r != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
    }
    pthread_mutex_lock(&w->mu);
    if (r == 0) {
      w->counters.written++;
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
  if (handle < 0 || handle > 1) {
    return;
  }
  pthread_mutex_lock(&w->mu);
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

void fw_ckpt_writer_flush(fw_ckpt_writer_t* w) {
  pthread_mutex_lock(&w->mu);
  while (w->state[0] == BUF_PENDING || w->state[0] == BUF_WRITING || w->state[1] == BUF_PENDING ||
         w->state[1] == BUF_WRITING) {
    pthread_cond_wait(&w->cv, &w->mu);
  }
  pthread_mutex_unlock(&w->mu);
}

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
  free(w->buf[0]);
  free(w->buf[1]);
  free(w);
}
