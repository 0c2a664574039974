// The engine's error type: the project-wide Status/Expected (common/status.h).
#pragma once

#include "common/status.h"

namespace collido::sim {
using collido::ErrorCode;
using collido::Expected;
using collido::invalid_argument;
using collido::io_error;
using collido::backend_error;
using collido::cancelled;
using collido::not_found;
using collido::parse_error;
using collido::resource_exhausted;
using collido::Status;
}  // namespace collido::sim
