// Error reporting of the renderer without exceptions. The renderer does not link
// the engine, so it has its own small Status (ok, or a message for a person).
#pragma once

#include <string>
#include <utility>

namespace collido::render {

class Status {
 public:
  Status() = default;
  static Status ok() { return {}; }
  static Status error(std::string message) { return Status(std::move(message)); }
  bool is_ok() const { return !failed_; }
  explicit operator bool() const { return !failed_; }
  const std::string& message() const { return message_; }

 private:
  explicit Status(std::string message) : failed_(true), message_(std::move(message)) {}
  bool failed_ = false;
  std::string message_;
};

}  // namespace collido::render
