// The renderer reports errors through the project-wide Status (common/status.h),
// a header-only convention, so the renderer still links no engine code.
#pragma once

#include "common/status.h"

namespace collido::render {
using collido::backend_error;
using collido::ErrorCode;
using collido::invalid_argument;
using collido::io_error;
using collido::Status;
}  // namespace collido::render
