// SPDX-License-Identifier: MIT
// A toy task for the actor's tests, and helpers to drive runs through it.
//
// The task: state (x, the last action), x in [0, 1] starts near 0.1; each step x += 0.02 (0.5 + a)
// + 0.002 N(0, 1) for the action a in [-1, 1]; the run ends with reward 1 at x >= 1 (terminal),
// or after 400 steps. gamma 0.99. Reaching the goal sooner is worth more, so the best action is
// +1 everywhere; the teacher drives at about 0 (a gain on nothing), with dither: an actor that
// only imitates it stays at 0, one that learns from the returns moves up.
#ifndef ACTOR_TEST_UTIL_H
#define ACTOR_TEST_UTIL_H

#include <actor/actor.h>
#include <rng/rng.h>

#include <stdint.h>

#define TOY_STEP_LIMIT 400

/// The actor's configuration for the toy task (small ring, defaults otherwise).
actor_config_t toy_config(void);

/// Storage for cfg (aligned; free with free()) and the actor in it.
actor_t* toy_actor(const actor_config_t* cfg, void** storage);

/// Who drives a toy run. TOY_FAIL: action -1 throughout, the run ends (terminal, reward 0) once
/// x < 0, like a collision that scores 0.
typedef enum toy_driver { TOY_TEACHER = 0, TOY_ACTOR = 1, TOY_FAIL = 2 } toy_driver_t;

/// One run recorded into the actor (the teacher: a = 0 + 0.3 N(0,1) on 20 % of steps; the actor:
/// its action + 0.1 N(0, 1) on 20 % of steps). Returns the steps taken.
int toy_run(actor_t* a, toy_driver_t driver, rng_t* rng);

/// The same with the action's effect on x per step (toy_run: 0.02); 0: the action changes nothing
/// but the state's last-action entry, x moves by exactly 0.01 a step and the goal lies at a
/// threshold drawn per run from [0.8, 1], so every slope of the return in the action is the value
/// model's noise, shared by the points of a run.
int toy_run_effect(actor_t* a, toy_driver_t driver, rng_t* rng, double effect);

/// Ends the run and does all its between-run work in slices of budget units; returns the slices.
uint64_t toy_end_run(actor_t* a, uint32_t budget);

/// `runs` runs of one driver, each ended with its between-run work in slices of 5,000 units.
void toy_runs(actor_t* a, toy_driver_t driver, rng_t* rng, int runs);

/// The actor's mean action over x = 0.05 .. 0.95 (last action 0).
double toy_mean_action(actor_t* a);

/// The actor's saved bytes (malloc'ed; *n their count).
uint8_t* toy_save(const actor_t* a, size_t* n);

#endif  // ACTOR_TEST_UTIL_H
