// Request heads, Range headers and path segments into the parsers the
// server's guard and router use before (or beside) Pistache's. Invariants: the
// framer cuts a connection's bytes into the same requests wherever a read
// ends, each head without a Content-Length; a
// head the guard passes comes out of the header cleaning with its target and
// no Content-Length (the guard keeps the body),
// a range lies inside the file, a decoded segment holds no NUL, an HTTP date
// reads back to itself, and a file's own entity tag matches it at the head of any list.
#include <cstdint>
#include <string>
#include <vector>

#include "service/http_parse.h"

using namespace collido::service;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const RequestHead h = parse_request_head(text);
  if (!h.bad_length && !h.chunked) {
    const RequestHead again = parse_request_head(head_for_pistache(text));
    if (again.bad_length || again.content_length != 0 || again.target != h.target) __builtin_trap();
  }
  // The input as a connection's bytes: the framer cuts the same requests (and
  // refuses the same way) whether they come in one read or two.
  {
    const auto limit = [](const RequestHead&, const void*) -> uint64_t { return 1 << 20; };
    const size_t cut = size ? data[0] % size : 0;
    RequestFramer once, twice;
    std::vector<RequestFramer::Whole> a, b;
    bool ask = false;
    const int code_a = once.feed(text.data(), text.size(), limit, nullptr, &a, &ask).code;
    int code_b = twice.feed(text.data(), cut, limit, nullptr, &b, &ask).code;
    if (!code_b)
      code_b = twice.feed(text.data() + cut, text.size() - cut, limit, nullptr, &b, &ask).code;
    if (code_a != code_b || a.size() != b.size()) __builtin_trap();
    for (size_t k = 0; k < a.size(); ++k)
      if (a[k].head != b[k].head || a[k].body != b[k].body ||
          parse_request_head(a[k].head.substr(0, a[k].head.size() - 4)).content_length != 0)
        __builtin_trap();
  }
  // The input's first line as a Range header, against a few file sizes.
  const std::string line = text.substr(0, text.find('\n'));
  for (uint64_t file_size : {uint64_t(0), uint64_t(1), uint64_t(1000), uint64_t(1) << 40}) {
    bool unsatisfiable = false;
    auto r = parse_range(line, file_size, &unsatisfiable);
    if (r && (unsatisfiable || r->first > r->second || r->second >= file_size)) __builtin_trap();
  }
  for (const std::string& segment : split_path(line)) {
    bool ok = true;
    const std::string decoded = percent_decode(segment, &ok);
    if (ok && decoded.find('\0') != std::string::npos) __builtin_trap();
  }
  // The same line as an HTTP date, and as If-None-Match and If-Range lists: a
  // date read back writes the same text, and a list that starts with a file's
  // own tag matches it, whatever follows.
  if (auto date = parse_http_date(line);
      date && http_date(*date) != line && parse_http_date(http_date(*date)) != date)
    __builtin_trap();
  const FileValidators v = file_validators(size, int64_t(size) * 7, 3);
  (void)range_applies(v, line);
  (void)not_modified(v, line, line);
  if (!not_modified(v, v.etag + ", " + line, "") || !range_applies(v, v.etag)) __builtin_trap();
  (void)html_escape(text);
  return 0;
}
