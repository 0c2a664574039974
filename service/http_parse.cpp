#include "service/http_parse.h"

#include <pistache/http_headers.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ctime>
#include <filesystem>

namespace collido::service {

namespace {
bool all_digits(const std::string& t) {
  return std::all_of(t.begin(), t.end(), [](unsigned char c) { return std::isdigit(c); });
}
}  // namespace

RequestHead parse_request_head(const std::string& head) {
  RequestHead h;
  bool first = true, seen_length = false, http11 = false;
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
      http11 = line.size() >= 9 && line.compare(line.size() - 9, 9, " HTTP/1.1") == 0;
      const auto a = line.find(' ');
      const auto b = a == std::string::npos ? a : line.find(' ', a + 1);
      h.method = line.substr(0, a);
      if (a != std::string::npos) h.target = line.substr(a + 1, b == std::string::npos ? b : b - a - 1);
      continue;
    }
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string key = line.substr(0, colon), value = line.substr(colon + 1);
    // Whitespace before the colon (RFC 9112 5.1: refused): "Content-Length :"
    // is a length to some parsers and not to others.
    if (!key.empty() && (key.back() == ' ' || key.back() == '\t')) {
      h.bad_length = true;
      return h;
    }
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
    } else if (key == "expect") {
      for (char& c : value) c = char(std::tolower((unsigned char)c));
      h.expects_continue = value == "100-continue";
    }
  }
  // A 1.0 client does not know interim answers (RFC 9110 10.1.1).
  h.expects_continue = h.expects_continue && http11;
  return h;
}

std::string head_for_pistache(const std::string& head) {
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
      std::string lower = name;
      for (char& c : lower) c = char(std::tolower((unsigned char)c));
      auto& registry = Pistache::Http::Header::Registry::instance();
      if (lower == "content-length") {
        keep = false;
      } else if (registry.isRegistered(name)) {
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

RequestFramer::Refusal RequestFramer::feed(const char* buf, size_t len, Limit limit,
                                           const void* context, std::vector<Whole>* whole,
                                           bool* ask_continue) {
  *ask_continue = false;
  const auto refuse = [this](int code, const char* reason, std::string message) {
    refused_ = true;
    head_.clear();
    return Refusal{code, reason, std::move(message)};
  };
  size_t i = 0;
  while (i < len && !refused_) {
    if (body_left_ > 0) {
      const size_t take = size_t(std::min<uint64_t>(body_left_, len - i));
      body_.append(buf + i, take);
      body_left_ -= take;
      i += take;
      if (body_left_ == 0) {
        whole->push_back({std::move(pending_head_), std::move(body_)});
        pending_head_.clear();
        body_.clear();
        *ask_continue = false;
      }
      continue;
    }
    const size_t before = head_.size();
    // At most a head's worth: the rest of the read is its body and the next
    // requests (a head that goes on past it is refused below).
    head_.append(buf + i, std::min(len - i, kMaxHeadBytes + 8));
    const size_t from = before >= 3 ? before - 3 : 0;
    const size_t end = head_.find("\r\n\r\n", from);
    // Too long whether or not its end came in this read.
    if (std::min(end, head_.size()) > kMaxHeadBytes)
      return refuse(431, "Request Header Fields Too Large", "the headers are too large");
    if (end == std::string::npos) break;
    const std::string head = head_.substr(0, end);
    i += end + 4 - before;
    head_.clear();
    const RequestHead h = parse_request_head(head);
    if (h.bad_length)
      return refuse(400, "Bad Request",
                    "a malformed head (its Content-Length, a bare CR or LF, or a space before "
                    "a colon)");
    if (h.chunked) return refuse(411, "Length Required", "send the body with a Content-Length");
    const uint64_t most = limit(h, context);
    if (h.content_length > most)
      return refuse(413, "Payload Too Large",
                    "the body is " + std::to_string(h.content_length) +
                        " bytes; this route takes at most " + std::to_string(most));
    std::string clean = head_for_pistache(head) + "\r\n\r\n";
    body_left_ = h.content_length;
    if (body_left_ == 0) {
      whole->push_back({std::move(clean), {}});
      continue;
    }
    pending_head_ = std::move(clean);
    *ask_continue = h.expects_continue && whole->empty();
  }
  return {};
}

FileValidators file_validators(uint64_t size, int64_t mtime_s, int64_t mtime_ns) {
  char tag[64];
  std::snprintf(tag, sizeof tag, "\"%llx-%llx\"", static_cast<unsigned long long>(size),
                static_cast<unsigned long long>(mtime_s) * 1000000000ull +
                    static_cast<unsigned long long>(mtime_ns));
  return {tag, mtime_s};
}

std::string http_date(int64_t unix_s) {
  const time_t t = time_t(unix_s);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char out[64];
  std::strftime(out, sizeof out, "%a, %d %b %Y %H:%M:%S GMT", &tm);
  return out;
}

std::optional<int64_t> parse_http_date(const std::string& text) {
  // Parsed by hand: strptime's names follow the locale.
  static const char* kDays[] = {"Sun", "Mon", "Tue", "Wed", "Thu", "Fri", "Sat"};
  static const char* kMonths[] = {"Jan", "Feb", "Mar", "Apr", "May", "Jun",
                                  "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"};
  if (text.size() != 29 || text.compare(3, 2, ", ") != 0 || text.compare(25, 4, " GMT") != 0 ||
      std::find_if(std::begin(kDays), std::end(kDays),
                   [&](const char* d) { return text.compare(0, 3, d) == 0; }) == std::end(kDays))
    return std::nullopt;
  auto digits = [&](size_t at, size_t n, int* v) {
    *v = 0;
    for (size_t i = at; i < at + n; ++i) {
      if (!std::isdigit(static_cast<unsigned char>(text[i]))) return false;
      *v = *v * 10 + (text[i] - '0');
    }
    return true;
  };
  int day, year, hour, minute, second;
  const auto month = std::find_if(std::begin(kMonths), std::end(kMonths),
                                  [&](const char* m) { return text.compare(8, 3, m) == 0; });
  if (month == std::end(kMonths) || text[7] != ' ' || text[11] != ' ' || text[16] != ' ' ||
      text[19] != ':' || text[22] != ':' || !digits(5, 2, &day) || !digits(12, 4, &year) ||
      !digits(17, 2, &hour) || !digits(20, 2, &minute) || !digits(23, 2, &second) || day < 1 ||
      day > 31 || hour > 23 || minute > 59 || second > 60)
    return std::nullopt;
  std::tm tm{};
  tm.tm_year = year - 1900, tm.tm_mon = int(month - std::begin(kMonths)), tm.tm_mday = day;
  tm.tm_hour = hour, tm.tm_min = minute, tm.tm_sec = second;
  return int64_t(timegm(&tm));
}

namespace {
// The entity tags of an If-None-Match or If-Range list, W/ kept.
std::vector<std::string> entity_tags(const std::string& list) {
  std::vector<std::string> tags;
  size_t i = 0;
  while (i < list.size()) {
    while (i < list.size() && (list[i] == ' ' || list[i] == '\t' || list[i] == ',')) ++i;
    if (i >= list.size()) break;
    const size_t start = i;
    if (list.compare(i, 2, "W/") == 0) i += 2;
    if (i < list.size() && list[i] == '"') {
      const size_t close = list.find('"', i + 1);
      if (close == std::string::npos) break;
      i = close + 1;
    } else {
      while (i < list.size() && list[i] != ',') ++i;
    }
    tags.push_back(list.substr(start, i - start));
  }
  return tags;
}
std::string opaque(const std::string& tag) {
  return tag.compare(0, 2, "W/") == 0 ? tag.substr(2) : tag;
}
}  // namespace

bool not_modified(const FileValidators& v, const std::string& if_none_match,
                  const std::string& if_modified_since) {
  if (!if_none_match.empty()) {
    for (const std::string& tag : entity_tags(if_none_match))
      if (tag == "*" || opaque(tag) == v.etag) return true;
    return false;
  }
  if (if_modified_since.empty()) return false;
  const auto since = parse_http_date(if_modified_since);
  return since && v.modified_s <= *since;
}

bool range_applies(const FileValidators& v, const std::string& if_range) {
  if (if_range.empty()) return true;
  if (if_range.front() == '"') return if_range == v.etag;  // strong comparison
  const auto date = parse_http_date(if_range);
  return date && *date == v.modified_s;
}

bool accepts_gzip(const std::string& accept_encoding) {
  bool named = false, star = false, named_zero = false;
  size_t at = 0;
  while (at <= accept_encoding.size()) {
    size_t end = accept_encoding.find(',', at);
    if (end == std::string::npos) end = accept_encoding.size();
    std::string item = accept_encoding.substr(at, end - at);
    at = end + 1;
    const size_t semi = item.find(';');
    std::string coding = item.substr(0, semi),
                params = semi == std::string::npos ? "" : item.substr(semi + 1);
    auto trim = [](std::string t) {
      const size_t a = t.find_first_not_of(" \t"), b = t.find_last_not_of(" \t");
      return a == std::string::npos ? std::string() : t.substr(a, b - a + 1);
    };
    coding = trim(coding);
    std::transform(coding.begin(), coding.end(), coding.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    // q=0 (0, 0.0, 0.00, 0.000) refuses the coding; anything else takes it.
    bool zero = false;
    params = trim(params);
    if ((params.size() > 2) && (params[0] == 'q' || params[0] == 'Q') && params[1] == '=') {
      const std::string q = trim(params.substr(2));
      zero = !q.empty() && q.find_first_not_of("0.") == std::string::npos;
    }
    if (coding == "gzip" || coding == "x-gzip") {
      if (zero)
        named_zero = true;
      else
        named = true;
    } else if (coding == "*" && !zero) {
      star = true;
    }
  }
  return named || (star && !named_zero);
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
