// The job cost model's inputs from disk: job logs (CSV, `calibrate --jobs` and the
// service's own) and job cost model files (JSON). The first byte picks the reader,
// the rest is the file. A log that parses must write itself back to the same text,
// and merging its repeats must give rows that validate and write back as well.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "job/cost_model.h"
#include "job/job_log.h"

namespace {

void check(bool ok) {
  if (!ok) std::abort();  // a broken invariant is a crash the fuzzer keeps
}

void job_log(const std::string& text) {
  using namespace collido::job;
  auto rows = parse_job_log(text);
  if (!rows) return;
  const std::string written = format_job_log(*rows);
  auto back = parse_job_log(written);
  check(bool(back));
  check(format_job_log(*back) == written);
  const std::vector<JobRecord> merged = merge_job_repeats(*rows);
  for (const JobRecord& r : merged) {
    check(bool(validate(r.inputs)));
    check(bool(validate(r.measure)));
  }
  check(bool(parse_job_log(format_job_log(merged))));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1)
    job_log(text);
  else
    (void)collido::job::JobCostModel::from_json(text);
  return 0;
}
