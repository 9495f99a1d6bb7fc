// SPDX-License-Identifier: MIT
// Operator input (operator.c): the B21R_TELEOP / B21R_COMMAND mailboxes.
#ifndef FW_OPERATOR_H
#define FW_OPERATOR_H

#include "loop_state.h"

void fw_operator_drain(fw_loop_t* L, int64_t now_us);

#endif  // FW_OPERATOR_H
