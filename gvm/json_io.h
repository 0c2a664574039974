// JSON conversion of the machine's parameters. Internal to gvm: only .cpp files of this
// module include it, so users of the library never see nlohmann types.
#pragma once

#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>

#include "gvm/machine.h"
#include "gvm/status.h"

namespace collido::gvm {

// A model field that is present but unusable (a float where an integer
// belongs, a count out of range). Thrown inside the readers only, caught with
// nlohmann's own errors and returned as a parse error.
struct BadField : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// j[key] as an integer of type T. nlohmann converts a number to an integer by
// a plain cast, undefined for 1e300 or a value out of T's range: checked here first.
template <class T>
T integer_at(const nlohmann::json& j, const char* key) {
  const nlohmann::json& v = j.at(key);
  const bool fits = v.is_number_unsigned()
                        ? v.get<uint64_t>() <= uint64_t(std::numeric_limits<T>::max())
                        : v.is_number_integer() &&
                              v.get<int64_t>() >= int64_t(std::numeric_limits<T>::min()) &&
                              (v.get<int64_t>() < 0 ||
                               uint64_t(v.get<int64_t>()) <= uint64_t(std::numeric_limits<T>::max()));
  if (!fits) throw BadField(std::string(key) + ": expected an integer in range, got " + v.dump());
  return v.get<T>();
}

// nlohmann writes doubles in a form that reads back to the same bits (Grisu2 with
// round-trip guarantee; parsing uses strtod), so plain JSON numbers suffice.
nlohmann::json machine_to_json(const MachineParams& p);

// Reads what machine_to_json wrote; shape and range checks are Machine::from_params's job.
Expected<MachineParams> machine_from_json(const nlohmann::json& j);

}  // namespace collido::gvm
