// Small command-line helpers shared by every `collidoscope` subcommand.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"

namespace collido::app {

// Exit codes of the command line: 0 success, 1 the work failed, 2 bad arguments.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

struct FlagSpec {
  std::string name;  // without the leading "--"
  bool takes_value;
  std::string help;  // one line for --help
};

// Parsed `--name value` / `--name` flags and positional arguments of one command.
class ParsedArgs {
 public:
  bool has(const std::string& name) const { return values_.count(name) != 0; }
  std::string get(const std::string& name, const std::string& fallback = "") const;
  const std::vector<std::string>& positional() const { return positional_; }

  // Typed accessors; on a malformed value they set *error and return the fallback.
  double get_double(const std::string& name, double fallback, std::string* error) const;
  int64_t get_int(const std::string& name, int64_t fallback, std::string* error) const;
  // The same for a flag held in an int: a value past int's range sets *error
  // (cast, 4294967297 would have been taken for 1 and passed the range checks).
  int get_int32(const std::string& name, int fallback, std::string* error) const;
  // An integer flag in [lo, hi] (fallback when absent); false with *error set
  // otherwise, so a value past int's range is refused rather than wrapped.
  bool get_int_in(const std::string& name, int64_t fallback, int64_t lo, int64_t hi, int* out,
                  std::string* error) const;

 private:
  friend std::optional<ParsedArgs> parse_args(const std::vector<std::string>&,
                                              const std::vector<FlagSpec>&, std::string*);
  std::map<std::string, std::string> values_;
  std::vector<std::string> positional_;
};

// Parses args against specs; unknown flags and missing values give nullopt and *error.
std::optional<ParsedArgs> parse_args(const std::vector<std::string>& args,
                                     const std::vector<FlagSpec>& specs, std::string* error);

// The one rule for exit codes: input errors (invalid argument, not found,
// unparsable) give kExitUsage, every other failure kExitFailure.
inline int exit_code(const Status& s) {
  if (s.is_ok()) return kExitOk;
  return is_input_error(s.code()) ? kExitUsage : kExitFailure;
}

// Prints "usage" followed by one line per flag.
void print_help(const std::string& usage, const std::vector<FlagSpec>& specs);

// Prints "collidoscope <command>: <message>" to stderr and returns kExitUsage.
int usage_error(const std::string& command, const std::string& message);

// A flag's comma-separated list ("a,b,c"); empty items are kept, so a
// stray comma reaches the caller's check as "".
std::vector<std::string> split_list(const std::string& s);

// Bytes for people: "512 B", "86.9 MiB", "1.4 GiB".
std::string human_bytes(double bytes);

// True when stdout/stderr is a terminal (progress bars) rather than a pipe or file.
bool stderr_is_terminal();

}  // namespace collido::app
