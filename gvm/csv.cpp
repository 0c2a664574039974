#include "gvm/csv.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace collido::gvm {

// RFC 4180: fields separated by commas, optionally in double quotes ("" inside quotes is
// one quote), records end at CR LF or LF; quoted fields may contain newlines.
Expected<std::vector<CsvRecord>> split_csv(const std::string& text) {
  std::vector<CsvRecord> out;
  int line = 1;
  size_t i = 0;
  const size_t n = text.size();
  while (i < n) {
    CsvRecord rec{line, {}};
    std::string field;
    bool quoted_any = false;
    for (;;) {
      field.clear();
      if (i < n && text[i] == '"') {
        quoted_any = true;
        const int open_line = line;
        ++i;
        for (;;) {
          if (i >= n)
            return parse_error("line " + std::to_string(open_line) + ", column " +
                               std::to_string(rec.fields.size() + 1) + ": unterminated quote");
          if (text[i] == '"') {
            if (i + 1 < n && text[i + 1] == '"') {
              field += '"';
              i += 2;
              continue;
            }
            ++i;
            break;
          }
          if (text[i] == '\n') ++line;
          field += text[i++];
        }
      } else {
        while (i < n && text[i] != ',' && text[i] != '\n' && text[i] != '\r') {
          if (text[i] == '"')
            return parse_error("line " + std::to_string(line) + ", column " +
                               std::to_string(rec.fields.size() + 1) +
                               ": quote inside an unquoted field");
          field += text[i++];
        }
      }
      rec.fields.push_back(field);
      if (i < n && text[i] == ',') {
        ++i;
        continue;
      }
      if (i < n && text[i] == '\r') ++i;
      if (i < n && text[i] == '\n') {
        ++i;
        ++line;
        break;
      }
      if (i >= n) break;
      return parse_error("line " + std::to_string(line) + ", column " +
                         std::to_string(rec.fields.size()) +
                         ": unexpected character after a closing quote");
    }
    // Blank lines separate nothing; skip them.
    if (rec.fields.size() == 1 && rec.fields[0].empty() && !quoted_any) continue;
    out.push_back(std::move(rec));
  }
  return out;
}

std::string trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && (s[a] == ' ' || s[a] == '\t')) ++a;
  while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t')) --b;
  return s.substr(a, b - a);
}

bool parse_int(const std::string& s, int64_t* out) {
  if (s.empty()) return false;
  const char* p = s.c_str();
  char* end = nullptr;
  errno = 0;
  long long v = std::strtoll(p, &end, 10);
  if (end != p && *end == '\0' && errno == 0) {
    *out = v;
    return true;
  }
  // Counts like 1e6 are integers too.
  errno = 0;
  double d = std::strtod(p, &end);
  if (end == p || *end != '\0' || errno != 0 || !std::isfinite(d) || d != std::floor(d) ||
      std::abs(d) > 9.0e18)
    return false;
  *out = static_cast<int64_t>(d);
  return true;
}

bool parse_double(const std::string& s, double* out) {
  if (s.empty()) return false;
  const char* p = s.c_str();
  char* end = nullptr;
  errno = 0;
  double d = std::strtod(p, &end);
  if (end == p || *end != '\0' || errno == ERANGE || !std::isfinite(d)) return false;
  *out = d;
  return true;
}

std::string quote_csv(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

std::string format_double(double d) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", d);
  return buf;
}

}  // namespace collido::gvm
