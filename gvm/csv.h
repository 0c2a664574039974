// CSV as the run logs write it (RFC 4180): records split into fields, and the
// number and text formats the logs use. Shared by the detection run log
// (gvm/run_log.h) and the job log (job/job_log.h).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "gvm/status.h"

namespace collido::gvm {

struct CsvRecord {
  int line;  // line where the record starts, 1-based
  std::vector<std::string> fields;
};

// RFC 4180: fields separated by commas, optionally in double quotes ("" inside quotes is
// one quote), records end at CR LF or LF; quoted fields may contain newlines. Blank
// lines are skipped. Errors name the line and column.
Expected<std::vector<CsvRecord>> split_csv(const std::string& text);

// Leading and trailing spaces and tabs removed.
std::string trim(const std::string& s);
// A whole number, also written as 1e6; false when it is not one.
bool parse_int(const std::string& s, int64_t* out);
// A finite number; false otherwise.
bool parse_double(const std::string& s, double* out);
// The field quoted when it holds a comma, quote or line break.
std::string quote_csv(const std::string& s);
// 17 significant digits: reads back bit-exactly.
std::string format_double(double d);

}  // namespace collido::gvm
