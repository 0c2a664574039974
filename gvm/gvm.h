// Entry header of the predictor module: run logs, the resource predictor (a general
// vector machine) and its baselines. Free of service, GPU and JSON-library types.
#pragma once

#include "gvm/baselines.h"
#include "gvm/evaluate.h"
#include "gvm/features.h"
#include "gvm/machine.h"
#include "gvm/predictor.h"
#include "gvm/run_log.h"
#include "gvm/status.h"
