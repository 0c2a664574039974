#include "app/cli.h"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace collido::app {

std::string ParsedArgs::get(const std::string& name, const std::string& fallback) const {
  auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second;
}

double ParsedArgs::get_double(const std::string& name, double fallback, std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  const char* s = it->second.c_str();
  char* end = nullptr;
  errno = 0;
  double v = std::strtod(s, &end);
  if (end == s || *end != '\0' || errno == ERANGE) {
    if (error) *error = "--" + name + " expects a number, got '" + it->second + "'";
    return fallback;
  }
  return v;
}

int64_t ParsedArgs::get_int(const std::string& name, int64_t fallback, std::string* error) const {
  auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  const char* s = it->second.c_str();
  char* end = nullptr;
  errno = 0;
  long long v = std::strtoll(s, &end, 10);
  if (end == s || *end != '\0' || errno == ERANGE) {
    // Accept 1e6-style integers, which people type for particle counts.
    // (Cast only what int64 holds: 1e30, inf and nan would be undefined.)
    double d = std::strtod(s, &end);
    if (end != s && *end == '\0' && std::isfinite(d) && std::fabs(d) < 9.2e18 && d == std::floor(d))
      return static_cast<int64_t>(d);
    if (error) *error = "--" + name + " expects an integer, got '" + it->second + "'";
    return fallback;
  }
  return v;
}

int ParsedArgs::get_int32(const std::string& name, int fallback, std::string* error) const {
  int v = fallback;
  std::string e;
  if (!get_int_in(name, fallback, INT32_MIN, INT32_MAX, &v, &e) && error && error->empty())
    *error = e;
  return v;
}

bool ParsedArgs::get_int_in(const std::string& name, int64_t fallback, int64_t lo, int64_t hi,
                            int* out, std::string* error) const {
  std::string e;
  const int64_t v = get_int(name, fallback, &e);
  if (!e.empty()) {
    *error = e;
    return false;
  }
  if (v < lo || v > hi) {
    *error = "--" + name + " must be in " + std::to_string(lo) + ".." + std::to_string(hi) +
             ", got " + std::to_string(v);
    return false;
  }
  *out = int(v);
  return true;
}

std::optional<ParsedArgs> parse_args(const std::vector<std::string>& args,
                                     const std::vector<FlagSpec>& specs, std::string* error) {
  ParsedArgs out;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a.size() > 2 && a.compare(0, 2, "--") == 0) {
      std::string name = a.substr(2), value;
      bool inline_value = false;
      if (auto eq = name.find('='); eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        inline_value = true;
      }
      const FlagSpec* spec = nullptr;
      for (const auto& s : specs)
        if (s.name == name) spec = &s;
      if (!spec) {
        *error = "unknown option --" + name + " (see --help)";
        return std::nullopt;
      }
      if (spec->takes_value && !inline_value) {
        if (i + 1 >= args.size()) {
          *error = "--" + name + " needs a value";
          return std::nullopt;
        }
        value = args[++i];
      } else if (!spec->takes_value && inline_value) {
        *error = "--" + name + " takes no value";
        return std::nullopt;
      }
      out.values_[name] = value;
    } else {
      out.positional_.push_back(a);
    }
  }
  return out;
}

void print_help(const std::string& usage, const std::vector<FlagSpec>& specs) {
  std::printf("%s\n\noptions:\n", usage.c_str());
  for (const auto& s : specs) {
    std::string left = "  --" + s.name + (s.takes_value ? " VALUE" : "");
    std::printf("%-28s %s\n", left.c_str(), s.help.c_str());
  }
}

int usage_error(const std::string& command, const std::string& message) {
  std::fprintf(stderr, "collidoscope %s: %s\n", command.c_str(), message.c_str());
  return kExitUsage;
}

bool stderr_is_terminal() { return isatty(fileno(stderr)) != 0; }

std::string human_bytes(double b) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int u = 0;
  while (b >= 1024.0 && u < 4) {
    b /= 1024.0;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, u ? "%.1f %s" : "%.0f %s", b, units[u]);
  return buf;
}

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  size_t pos = 0;
  while (pos <= s.size()) {
    const size_t c = s.find(',', pos);
    out.push_back(s.substr(pos, c == std::string::npos ? std::string::npos : c - pos));
    if (c == std::string::npos) break;
    pos = c + 1;
  }
  return out;
}

}  // namespace collido::app
