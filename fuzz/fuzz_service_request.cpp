// JSON request bodies into the job service's validation: predictions, start
// previews (the placement itself), job submissions, models and accounts.
// Whatever the body, the answer is a 2xx or a 4xx with a message: a 5xx means
// an input reached something it should not.
// The service lives in a temporary data folder; no worker runs, so submitted
// jobs stay queued. The committed CPU job cost model prices them where the build
// knows the source folder, so odd scenes reach the model too.
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "service/job_service.h"

using namespace collido::service;

namespace {

struct Fixture {
  std::unique_ptr<JobService> service;
  User user;
  std::string dir;
  Fixture() {
    dir = (std::filesystem::temp_directory_path() / ("fuzz_service_" + std::to_string(::getpid()))).string();
    std::filesystem::remove_all(dir);
    ServiceConfig c;
    c.data_dir = dir;
    c.job_executable = "/bin/false";
    c.max_queued_per_user = 1 << 30;
    c.retrain_every = 0;
#ifdef COLLIDO_SOURCE_DIR
    const std::string model = std::string(COLLIDO_SOURCE_DIR) + "/bench/data/job_model_cpu.json";
    if (std::filesystem::exists(model)) c.cost_models = {model};
#endif
    auto s = JobService::open(c);
    if (!s) std::abort();
    service = std::move(*s);
    service->create_account({{"name", "fuzz"}, {"password", "fuzz-password-1"}});
    std::string token;
    service->create_session({{"name", "fuzz"}, {"password", "fuzz-password-1"}}, unix_now(), &token);
    auto u = service->authenticate(token);
    if (!u) std::abort();
    user = *u;
  }
  ~Fixture() { std::filesystem::remove_all(dir); }
};

void check(const Reply& r) {
  if (r.status < 200 || r.status >= 500) __builtin_trap();
  if (r.status >= 400 && !r.body.contains("error")) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Fixture f;
  const json body = json::parse(reinterpret_cast<const char*>(data), reinterpret_cast<const char*>(data) + size,
                                nullptr, false);
  if (body.is_discarded()) return 0;
  check(f.service->predict(f.user, body));
  check(f.service->start_preview(f.user, body));
  check(f.service->submit(f.user, body));
  check(f.service->create_model(f.user, body));
  check(f.service->create_account(body));
  return 0;
}
