// JSON conversion of the machine's parameters. Internal to gvm: only .cpp files of this
// module include it, so users of the library never see nlohmann types.
#pragma once

#include <nlohmann/json.hpp>

#include "gvm/machine.h"
#include "gvm/status.h"

namespace collido::gvm {

// nlohmann writes doubles in a form that reads back to the same bits (Grisu2 with
// round-trip guarantee; parsing uses strtod), so plain JSON numbers suffice.
nlohmann::json machine_to_json(const MachineParams& p);

// Reads what machine_to_json wrote; shape and range checks are Machine::from_params's job.
Expected<MachineParams> machine_from_json(const nlohmann::json& j);

}  // namespace collido::gvm
