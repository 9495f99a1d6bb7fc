// SPDX-License-Identifier: MIT
// Touching memory before the loop starts (fw/prefault.h).
#include "fw/prefault.h"

void fw_prefault(void* p, size_t n) {
  if (p == NULL || n == 0U) {
    return;
  }
  volatile uint8_t* b = p;
  for (size_t i = 0; i < n; i += FW_PREFAULT_PAGE_BYTES) {
    b[i] = b[i];
  }
  b[n - 1U] = b[n - 1U];
}
