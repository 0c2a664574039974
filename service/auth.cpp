#include "service/auth.h"

#include <sodium.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace collido::service {

bool init_crypto() { return sodium_init() >= 0; }

Expected<std::string> hash_password(const std::string& password) {
  char out[crypto_pwhash_STRBYTES];
  if (crypto_pwhash_str(out, password.data(), password.size(),
                        crypto_pwhash_OPSLIMIT_INTERACTIVE,
                        crypto_pwhash_MEMLIMIT_INTERACTIVE) != 0)
    return resource_exhausted("password hashing ran out of memory");
  return std::string(out);
}

bool verify_password(const std::string& hash, const std::string& password) {
  if (hash.empty() || hash.size() >= crypto_pwhash_STRBYTES) return false;
  char buf[crypto_pwhash_STRBYTES] = {};
  std::copy(hash.begin(), hash.end(), buf);
  return crypto_pwhash_str_verify(buf, password.data(), password.size()) == 0;
}

std::string random_token(size_t bytes) {
  std::string raw(bytes, '\0');
  randombytes_buf(raw.data(), raw.size());
  std::string out(sodium_base64_ENCODED_LEN(bytes, sodium_base64_VARIANT_URLSAFE_NO_PADDING), '\0');
  sodium_bin2base64(out.data(), out.size(), reinterpret_cast<const unsigned char*>(raw.data()),
                    raw.size(), sodium_base64_VARIANT_URLSAFE_NO_PADDING);
  out.resize(std::strlen(out.c_str()));
  return out;
}

std::string sha256_hex(const std::string& data) {
  unsigned char h[crypto_hash_sha256_BYTES];
  crypto_hash_sha256(h, reinterpret_cast<const unsigned char*>(data.data()), data.size());
  char hex[2 * crypto_hash_sha256_BYTES + 1];
  sodium_bin2hex(hex, sizeof hex, h, sizeof h);
  return hex;
}

double LoginThrottle::wait_s(const std::string& name, double now) {
  std::lock_guard lock(mu_);
  auto it = entries_.find(name);
  if (it == entries_.end()) return 0;
  return std::max(0.0, it->second.next_try - now);
}

void LoginThrottle::failed(const std::string& name, double now) {
  std::lock_guard lock(mu_);
  // A bounded table: a flood of made-up names must not grow memory without end.
  if (entries_.size() > 100000) entries_.clear();
  Entry& e = entries_[name];
  ++e.failures;
  if (e.failures >= free_tries_) {
    const int over = e.failures - free_tries_;
    e.next_try = now + std::min(300.0, std::ldexp(1.0, std::min(over, 16)));
  }
}

void LoginThrottle::succeeded(const std::string& name) {
  std::lock_guard lock(mu_);
  entries_.erase(name);
}

}  // namespace collido::service
