#include "service/http_parse.h"

#include <pistache/http_headers.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

namespace collido::service {

namespace {
bool all_digits(const std::string& t) {
  return std::all_of(t.begin(), t.end(), [](unsigned char c) { return std::isdigit(c); });
}
}  // namespace

RequestHead parse_request_head(const std::string& head) {
  RequestHead h;
  bool first = true, seen_length = false;
  size_t pos = 0;
  while (pos <= head.size()) {
    size_t eol = head.find("\r\n", pos);
    if (eol == std::string::npos) eol = head.size();
    const std::string line = head.substr(pos, eol - pos);
    pos = eol + 2;
    if (line.find_first_of("\r\n") != std::string::npos) {
      h.bad_length = true;
      return h;
    }
    if (first) {
      first = false;
      const auto a = line.find(' ');
      const auto b = a == std::string::npos ? a : line.find(' ', a + 1);
      h.method = line.substr(0, a);
      if (a != std::string::npos) h.target = line.substr(a + 1, b == std::string::npos ? b : b - a - 1);
      continue;
    }
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string key = line.substr(0, colon), value = line.substr(colon + 1);
    for (char& c : key) c = char(std::tolower((unsigned char)c));
    value.erase(0, value.find_first_not_of(" \t"));
    while (!value.empty() && (value.back() == ' ' || value.back() == '\t')) value.pop_back();
    if (key == "content-length") {
      if (value.empty() || value.size() > 19 || !all_digits(value) ||
          (seen_length && std::stoull(value) != h.content_length)) {
        h.bad_length = true;
        return h;
      }
      h.content_length = std::stoull(value);
      seen_length = true;
    } else if (key == "authorization") {
      if (value.compare(0, 7, "Bearer ") == 0) h.bearer = value.substr(7);
    } else if (key == "cookie") {
      h.cookies = value;
    } else if (key == "transfer-encoding") {
      for (char& c : value) c = char(std::tolower((unsigned char)c));
      if (value.find("chunked") != std::string::npos) h.chunked = true;
    }
  }
  return h;
}

std::string without_unparsable_headers(const std::string& head) {
  std::string out;
  size_t pos = 0;
  bool first = true;
  while (pos <= head.size()) {
    size_t eol = head.find("\r\n", pos);
    if (eol == std::string::npos) eol = head.size();
    const std::string line = head.substr(pos, eol - pos);
    pos = eol + 2;
    bool keep = true;
    const auto colon = line.find(':');
    if (!first && colon != std::string::npos) {
      const std::string name = line.substr(0, colon);
      std::string value = line.substr(colon + 1);
      value.erase(0, value.find_first_not_of(" \t"));
      auto& registry = Pistache::Http::Header::Registry::instance();
      if (registry.isRegistered(name)) {
        try {
          registry.makeHeader(name)->parseRaw(value.data(), value.size());
        } catch (...) {
          keep = false;
        }
      }
    }
    if (keep) {
      if (!first) out += "\r\n";
      out += line;
    }
    first = false;
  }
  return out;
}

std::optional<std::pair<uint64_t, uint64_t>> parse_range(const std::string& header, uint64_t size,
                                                         bool* unsatisfiable) {
  *unsatisfiable = false;
  const std::string prefix = "bytes=";
  if (header.compare(0, prefix.size(), prefix) != 0) return std::nullopt;
  const std::string spec = header.substr(prefix.size());
  if (spec.find(',') != std::string::npos) return std::nullopt;
  const auto dash = spec.find('-');
  if (dash == std::string::npos) return std::nullopt;
  auto number = [](const std::string& t, uint64_t* v) {
    if (t.empty() || t.size() > 19 || !all_digits(t)) return false;
    *v = std::stoull(t);
    return true;
  };
  const std::string a = spec.substr(0, dash), b = spec.substr(dash + 1);
  uint64_t first = 0, last = 0;
  if (a.empty()) {  // the last N bytes
    uint64_t n = 0;
    if (!number(b, &n)) return std::nullopt;
    if (n == 0 || size == 0) {
      *unsatisfiable = true;
      return std::nullopt;
    }
    first = n >= size ? 0 : size - n;
    last = size - 1;
  } else {
    if (!number(a, &first)) return std::nullopt;
    if (b.empty()) {
      last = size ? size - 1 : 0;
    } else {
      if (!number(b, &last) || last < first) return std::nullopt;
      last = std::min(last, size ? size - 1 : 0);
    }
    if (first >= size) {
      *unsatisfiable = true;
      return std::nullopt;
    }
  }
  return std::make_pair(first, last);
}

std::string percent_decode(const std::string& s, bool* ok) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%') {
      if (i + 2 >= s.size() || !std::isxdigit((unsigned char)s[i + 1]) ||
          !std::isxdigit((unsigned char)s[i + 2])) {
        *ok = false;
        return {};
      }
      out += char(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  if (out.find('\0') != std::string::npos) *ok = false;
  return out;
}

std::vector<std::string> split_path(const std::string& path) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= path.size()) {
    size_t end = path.find('/', start);
    if (end == std::string::npos) end = path.size();
    if (end > start) out.emplace_back(path, start, end - start);
    start = end + 1;
  }
  return out;
}

std::string html_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string web_mime_type(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  static const std::pair<const char*, const char*> kTypes[] = {
      {".html", "text/html; charset=utf-8"}, {".js", "text/javascript; charset=utf-8"},
      {".mjs", "text/javascript; charset=utf-8"}, {".css", "text/css; charset=utf-8"},
      {".svg", "image/svg+xml"}, {".ico", "image/x-icon"}, {".png", "image/png"},
      {".json", "application/json"}, {".map", "application/json"}, {".woff2", "font/woff2"},
      {".txt", "text/plain; charset=utf-8"}};
  for (const auto& [e, type] : kTypes)
    if (ext == e) return type;
  return "application/octet-stream";
}

}  // namespace collido::service
