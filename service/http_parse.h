// The pieces of HTTP the server reads itself, before or beside Pistache's
// parser: request heads (the guard's limits), Range headers, paths. Pure
// functions of their text, so they are fuzzed (fuzz/fuzz_http.cpp) and tested
// without a socket.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace collido::service {

// What the guard needs of a request head (the bytes before the blank line).
struct RequestHead {
  std::string method;           // the request line's method: "PUT"
  std::string target;           // the request line's target: "/api/v1/jobs?x=1"
  std::string bearer;           // an Authorization header's Bearer token
  std::string cookies;          // the Cookie header's value
  uint64_t content_length = 0;  // 0 when absent
  bool chunked = false;         // Transfer-Encoding names chunked
  bool expects_continue = false;  // HTTP/1.1 with Expect: 100-continue
  // A Content-Length that is not a plain number, two that disagree, a bare
  // CR or LF inside the head, or whitespace before a header's colon (read
  // differently by different parsers: refused).
  bool bad_length = false;
};
RequestHead parse_request_head(const std::string& head);

// The head as the guard hands it to Pistache 0.0.5: without the header lines
// Pistache would fail to parse, and without Content-Length (the guard keeps
// the body itself; Pistache's parser walked a body a byte at a time on the
// reactor thread). Pistache parses the headers it knows (Content-Type,
// Accept, Host, ...) and answers 415 or 400 for the whole request when one
// fails: a `Content-Type: model/stl` upload (the registered type for STL)
// would be refused. None of those headers steers a route of ours, so a line
// whose value does not parse is dropped instead.
std::string head_for_pistache(const std::string& head);

// A connection's bytes cut into whole requests, whatever the reads'
// boundaries: each request's head (as head_for_pistache gives it, with its
// blank line) and its body, counted by Content-Length. The guard keeps the
// body; Pistache parses the head alone. A head that fails the checks refuses
// its request and everything after it (the framer then takes nothing more).
class RequestFramer {
 public:
  struct Whole {
    std::string head, body;
  };
  struct Refusal {
    int code = 0;  // 0: none
    const char* reason = "";
    std::string message;
  };
  // The largest body the request of a head may carry.
  using Limit = uint64_t (*)(const RequestHead&, const void* context);
  static constexpr size_t kMaxHeadBytes = 16 << 10;  // 431 beyond

  // Appends the requests these bytes complete to *whole; returns a refusal
  // (code != 0) when a head is refused. *ask_continue: the last head read
  // here asks to hear whether to send its body (Expect: 100-continue), no
  // request came whole before it in these bytes, and its body is still to
  // come.
  Refusal feed(const char* buf, size_t len, Limit limit, const void* context,
               std::vector<Whole>* whole, bool* ask_continue);
  bool refused() const { return refused_; }

 private:
  std::string head_;          // header bytes of the request being read
  std::string pending_head_;  // a whole head (for Pistache) while its body comes
  std::string body_;          // that body so far
  uint64_t body_left_ = 0;    // its bytes still to come
  bool refused_ = false;
};

// A byte range of a file of `size` bytes from a Range header: first and last
// byte. nullopt = answer the whole file (no header, a syntax we ignore, or
// several ranges, which RFC 9110 lets a server answer whole); *unsatisfiable
// when the range starts beyond the end.
std::optional<std::pair<uint64_t, uint64_t>> parse_range(const std::string& header, uint64_t size,
                                                         bool* unsatisfiable);

// Conditional requests (RFC 9110 13) on a file, whose validators are an
// entity tag of its size and modification time and its Last-Modified date.
struct FileValidators {
  std::string etag;        // "\"<size hex>-<mtime ns hex>\"": a new file, a new tag
  int64_t modified_s = 0;  // the modification time, whole seconds since 1970 (UTC)
};
FileValidators file_validators(uint64_t size, int64_t mtime_s, int64_t mtime_ns);
// An IMF-fixdate ("Sun, 06 Nov 1994 08:49:37 GMT"), and back: nullopt for
// any other text (the obsolete formats are not read; the date is then ignored).
std::string http_date(int64_t unix_s);
std::optional<int64_t> parse_http_date(const std::string& text);
// Whether a GET may be answered 304: If-None-Match (a list of tags or "*",
// compared weakly) decides when present, else If-Modified-Since. Empty
// strings stand for absent headers.
bool not_modified(const FileValidators& v, const std::string& if_none_match,
                  const std::string& if_modified_since);
// Whether a Range applies under If-Range (absent: yes): only to the very file
// the client holds part of, its strong tag or its exact date.
bool range_applies(const FileValidators& v, const std::string& if_range);

// Whether an Accept-Encoding header takes gzip: named, or "*", with a q
// above 0 (RFC 9110 12.5.3).
bool accepts_gzip(const std::string& accept_encoding);

// %XX decoding of one path segment; *ok = false on a malformed escape or a NUL.
std::string percent_decode(const std::string& s, bool* ok);
// The non-empty segments of a path ("/a//b/" -> {"a", "b"}).
std::vector<std::string> split_path(const std::string& path);
std::string html_escape(const std::string& s);
// The web UI's file types (a run's own files take job::mime_type).
std::string web_mime_type(const std::string& path);

}  // namespace collido::service
