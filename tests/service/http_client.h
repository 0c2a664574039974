// A small blocking HTTP client over libcurl for the service tests.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace collido::test {

struct HttpResponse {
  long status = 0;          // 0 = no answer (connection failed)
  std::string body;
  std::map<std::string, std::string> headers;  // names lower-case
  std::string error;        // curl's message when status is 0
};

// One request; headers as "Name: value". Times out after timeout_s.
HttpResponse http(const std::string& method, const std::string& url, const std::string& body = "",
                  const std::vector<std::string>& headers = {}, double timeout_s = 30);

}  // namespace collido::test
