// What the service's tests share: a temporary folder, a file's bytes, a small
// job, and a client that signs up, calls the API and waits for jobs (libcurl).
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/scratch.h"
#include "tests/service/http_client.h"

namespace collido::test {

using json = nlohmann::json;

// A fresh folder for the test, gone when it passes (tests/scratch.h).
inline std::string temp_dir(const std::string& name) {
  return scratch_dir(name);
}

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A scene that runs in about a second on one thread, rendered small.
inline json tiny_job(const json& wall, int particles = 40, double duration = 0.3) {
  return {{"scene",
           {{"wall", wall},
            {"particles", {{"count", particles}, {"radius", 0.5}}},
            {"placement", {{"kind", "pour"}}},
            {"duration", duration},
            {"fps", 10}}},
          {"render", {{"width", 160}, {"height", 96}, {"formats", {"mp4", "gif"}}}}};
}

class Client {
 public:
  explicit Client(std::string base) : base_(std::move(base)) {}
  HttpResponse call(const std::string& method, const std::string& path, const std::string& body = "",
                    std::vector<std::string> headers = {}) const {
    if (!token.empty()) headers.push_back("Authorization: Bearer " + token);
    return http(method, base_ + path, body, headers);
  }
  json call_json(const std::string& method, const std::string& path, const json& body = nullptr,
                 long expect = 200) const {
    auto r = call(method, path, body.is_null() ? "" : body.dump());
    EXPECT_EQ(r.status, expect) << method << " " << path << ": " << r.body;
    return json::parse(r.body, nullptr, false);
  }
  // Makes an account and signs in with it.
  void sign_up(const std::string& name, const std::string& password = "correct horse") {
    call_json("POST", "/api/v1/accounts", {{"name", name}, {"password", password}}, 201);
    token = call_json("POST", "/api/v1/sessions", {{"name", name}, {"password", password}})["token"];
  }
  // Polls a job until it ends (or the bound passes); the last view of it.
  json wait_job(const std::string& id, double bound_s = 180) const {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(bound_s);
    json j;
    while (std::chrono::steady_clock::now() < end) {
      j = call_json("GET", "/api/v1/jobs/" + id);
      const std::string s = j.value("state", "");
      if (s == "done" || s == "failed" || s == "cancelled") return j;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    ADD_FAILURE() << "job " << id << " did not end in " << bound_s << " s: " << j.dump();
    return j;
  }
  std::string token;
  const std::string& base() const { return base_; }

 private:
  std::string base_;
};

}  // namespace collido::test
