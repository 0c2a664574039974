// The engine's error type: the project-wide Status/Expected (common/status.h).
#pragma once

#include "common/status.h"

namespace collido::sim {
using collido::ErrorCode;
using collido::Expected;
using collido::invalid_argument;
using collido::io_error;
using collido::parse_error;
using collido::Status;
}  // namespace collido::sim
