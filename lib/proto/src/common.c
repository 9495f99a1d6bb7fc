// SPDX-License-Identifier: MIT
// Names of the shared status codes of lib/proto.
#include <proto/common.h>

const char* proto_status_name(proto_status_t status) {
  switch (status) {
    case PROTO_OK:
      return "PROTO_OK";
    case PROTO_ERR_INVALID_ARG:
      return "PROTO_ERR_INVALID_ARG";
    case PROTO_ERR_CAPACITY:
      return "PROTO_ERR_CAPACITY";
    case PROTO_ERR_FORMAT:
      return "PROTO_ERR_FORMAT";
    case PROTO_ERR_RANGE:
      return "PROTO_ERR_RANGE";
  }
  return "PROTO_ERR_UNKNOWN";
}
