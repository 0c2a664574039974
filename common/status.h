// Error reporting without exceptions, shared by every module: library code
// returns a Status or an Expected<T>; the command line and the service turn them
// into messages and HTTP codes. Header-only, so sharing it links nothing.
#pragma once

#include <string>
#include <utility>
#include <variant>

namespace collido {

// One set of codes for every module; the command line maps them to exit codes
// (kInvalidArgument, kNotFound, kParse: 2, bad input; the rest: 1, a failed run)
// and the service to HTTP (400/404/422, 409 or 507, 499-like cancellation, 500).
enum class ErrorCode {
  kOk = 0,
  kInvalidArgument,   // the input says something impossible or malformed
  kNotFound,          // a file, id or key that does not exist
  kIo,                // reading or writing failed
  kParse,             // a file's contents do not parse
  kResourceExhausted, // over a memory or work budget, or an allocation failed
  kCancelled,         // stopped on request
  kBackend,           // the GPU, GL or an encoder failed
};

class Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message) : code_(code), message_(std::move(message)) {}
  static Status ok() { return {}; }
  bool is_ok() const { return code_ == ErrorCode::kOk; }
  explicit operator bool() const { return is_ok(); }
  ErrorCode code() const { return code_; }
  const std::string& message() const { return message_; }

 private:
  ErrorCode code_ = ErrorCode::kOk;
  std::string message_;
};

inline Status invalid_argument(std::string m) { return {ErrorCode::kInvalidArgument, std::move(m)}; }
inline Status io_error(std::string m) { return {ErrorCode::kIo, std::move(m)}; }
inline Status parse_error(std::string m) { return {ErrorCode::kParse, std::move(m)}; }
inline Status not_found(std::string m) { return {ErrorCode::kNotFound, std::move(m)}; }
inline Status resource_exhausted(std::string m) {
  return {ErrorCode::kResourceExhausted, std::move(m)};
}
inline Status cancelled(std::string m) { return {ErrorCode::kCancelled, std::move(m)}; }
inline Status backend_error(std::string m) { return {ErrorCode::kBackend, std::move(m)}; }

// True for the codes that mean the caller's input was wrong (exit code 2).
inline bool is_input_error(ErrorCode c) {
  return c == ErrorCode::kInvalidArgument || c == ErrorCode::kNotFound || c == ErrorCode::kParse;
}
// The name of a code, for JSON documents and logs ("invalid_argument", ...).
inline const char* to_string(ErrorCode c) {
  switch (c) {
    case ErrorCode::kOk: return "ok";
    case ErrorCode::kInvalidArgument: return "invalid_argument";
    case ErrorCode::kNotFound: return "not_found";
    case ErrorCode::kIo: return "io";
    case ErrorCode::kParse: return "parse";
    case ErrorCode::kResourceExhausted: return "resource_exhausted";
    case ErrorCode::kCancelled: return "cancelled";
    case ErrorCode::kBackend: return "backend";
  }
  return "unknown";
}

// A value or the Status that explains why there is none.
template <class T>
class Expected {
 public:
  Expected(T value) : v_(std::move(value)) {}
  Expected(Status error) : v_(std::move(error)) {}
  bool has_value() const { return v_.index() == 0; }
  explicit operator bool() const { return has_value(); }
  T& value() { return std::get<0>(v_); }
  const T& value() const { return std::get<0>(v_); }
  T& operator*() { return value(); }
  const T& operator*() const { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  const Status& status() const {
    static const Status ok_status;
    return has_value() ? ok_status : std::get<1>(v_);
  }

 private:
  std::variant<T, Status> v_;
};

}  // namespace collido
