// SPDX-License-Identifier: MIT
/// proto/common.h — Status codes and conventions shared by the byte codecs of lib/proto.
///
/// Conventions for every codec in lib/proto (LMS200, rFLEX, CANopen):
/// - Pure functions over caller-owned memory: no file descriptors, no clocks, no allocation,
///   no globals. Every state struct has a compile-time size, so it can be `static`.
/// - Encoders write into a caller buffer of stated capacity and return the number of bytes
///   written, or 0 when an argument is invalid or the buffer is too small; they never write
///   beyond `cap` and leave the buffer contents unspecified on failure.
/// - Streaming decoders are fed arbitrary chunks of bytes (one byte at a time or thousands),
///   return how many bytes they consumed and at most one event per call, resynchronise after
///   garbage, and count every byte or frame they drop, by reason. Counters never decrease.
/// - Not thread-safe: one state struct per stream, used by one thread at a time.
/// - Protocol units (counts, centimetres, 0.01°) stay inside lib/proto; typed results are SI.
#ifndef PROTO_COMMON_H
#define PROTO_COMMON_H

#ifdef __cplusplus
extern "C" {
#endif

/// Result of the typed parsers and other non-encoder functions of lib/proto.
typedef enum proto_status {
  PROTO_OK = 0,
  PROTO_ERR_INVALID_ARG = 2,  ///< NULL pointer or value outside its documented range (1 unused).
  PROTO_ERR_CAPACITY,         ///< Output or message does not fit a documented capacity.
  PROTO_ERR_FORMAT,           ///< Message has the wrong code, length or layout for this parser.
  PROTO_ERR_RANGE,            ///< Message is well formed but a field holds a value outside its range.
} proto_status_t;

/// Short constant name of a status ("PROTO_OK", ...), never NULL. O(1).
const char* proto_status_name(proto_status_t status);

#ifdef __cplusplus
}
#endif

#endif  // PROTO_COMMON_H
