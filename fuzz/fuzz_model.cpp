// The predictor's inputs from disk: run logs (CSV) and model files (JSON).
// The first byte picks the reader, the rest is the file.
#include <cstdint>
#include <string>

#include "gvm/predictor.h"
#include "gvm/run_log.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] & 1)
    (void)collido::gvm::parse_run_log(text);
  else
    (void)collido::gvm::ResourcePredictor::from_json(text);
  return 0;
}
