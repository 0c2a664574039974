// Passwords, session tokens and the brake on password guessing.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>

#include "common/status.h"

namespace collido::service {

// Calls sodium_init(); false when libsodium cannot start (no entropy source).
bool init_crypto();

// Argon2id (libsodium's crypto_pwhash_str at its interactive limits: 64 MiB,
// about 0.1 s here). The string holds its own salt and parameters.
Expected<std::string> hash_password(const std::string& password);
bool verify_password(const std::string& hash, const std::string& password);

// 32 random bytes as 43 URL-safe base64 characters (session tokens, share
// tokens), and a job id of 16 random bytes (22 characters).
std::string random_token(size_t bytes = 32);

// SHA-256 as lower-case hex (what sessions are stored under, result keys).
std::string sha256_hex(const std::string& data);

// Slows down repeated wrong passwords for a name: after `free_tries` failures
// in a row each further try must wait twice as long as the last (1 s, 2 s, ...,
// up to 5 minutes). It never sleeps on a request thread: a try that comes too
// early is refused with the seconds to wait (HTTP 429, Retry-After).
class LoginThrottle {
 public:
  explicit LoginThrottle(int free_tries = 3) : free_tries_(free_tries) {}
  // Seconds the name must still wait before its next try; 0 = may try now.
  double wait_s(const std::string& name, double now);
  void failed(const std::string& name, double now);
  void succeeded(const std::string& name);

 private:
  struct Entry {
    int failures = 0;
    double next_try = 0;
  };
  std::mutex mu_;
  std::map<std::string, Entry> entries_;
  int free_tries_;
};

}  // namespace collido::service
