// SPDX-License-Identifier: MIT
/// features/features.h — Laser scan + odometry -> task state for the declared tasks.
///
/// Umbrella header: the scan and pose types (scan.h), the corridor-following state
/// (corridor.h), the obstacle-avoidance state (obstacles.h) and the doorway-passing state
/// (doorway.h). Every function of the module is
/// pure, allocation-free, bounded in time (linear in the number of beams, see each header) and
/// never produces NaN: missing information is reported through validity flags.
#ifndef B21R_FEATURES_FEATURES_H
#define B21R_FEATURES_FEATURES_H

#include "features/corridor.h"
#include "features/doorway.h"
#include "features/obstacles.h"
#include "features/scan.h"

#endif  // B21R_FEATURES_FEATURES_H
