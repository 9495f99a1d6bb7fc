#!/bin/sh
# SPDX-License-Identifier: MIT
# Runs inside netns-run: one process subscribes, another publishes over udpm multicast routed on
# the namespace's loopback. Passes when the subscriber receives the publisher's message.
set -eu
probe="$1"
url="udpm://239.255.76.67:7667?ttl=0"
"$probe" subscribe "$url" B21R_TELEOP &
sub=$!
"$probe" publish "$url" B21R_TELEOP &
pub=$!
status=0
wait "$sub" || status=$?
kill "$pub" 2>/dev/null || true
wait "$pub" 2>/dev/null || true
if [ "$status" -eq 0 ]; then
  echo "lcm_two_process: message crossed processes over udpm in a private network namespace"
fi
exit "$status"
