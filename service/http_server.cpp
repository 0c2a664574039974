#include "service/http_server.h"

#include <fcntl.h>
#include <signal.h>
#include <strings.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <pistache/endpoint.h>
#include <pistache/http.h>
#include <pistache/peer.h>
#include <algorithm>
#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <utility>

#include "job/run_dir.h"
#include "service/http_parse.h"
#include "service/request_pool.h"

namespace collido::service {

namespace fs = std::filesystem;
using namespace Pistache;

namespace {

constexpr const char* kSessionCookie = "collido_session";

// ---- requests and responses -------------------------------------------------

struct Request {
  std::string method;
  std::vector<std::string> segments;  // the path, split and percent-decoded
  std::map<std::string, std::string> params;  // {name} and {path*} captures
  const Http::Request* http = nullptr;
  std::optional<User> user;
  std::string token;  // the session token the request came with
  std::string body;   // as the guard kept it (Pistache's request has none)
  std::string query(const std::string& key) const {
    auto v = http->query().get(key);
    return v ? *v : std::string();
  }
};

// A file held open for its answer: what was opened is what is sent, even if
// the name is replaced (a re-render) or removed (a deleted job) meanwhile.
struct OpenFile {
  int fd = -1;
  ~OpenFile() {
    if (fd >= 0) ::close(fd);
  }
};
struct FileBody {
  std::shared_ptr<const OpenFile> file;
  uint64_t first = 0, count = 0;
};

struct Response {
  int status = 200;
  std::string body;
  std::optional<FileBody> file;  // set: the body is this part of a file, sent in slices
  std::string mime = "application/json";
  std::vector<std::pair<std::string, std::string>> headers;

  // Sets a header, replacing one of the same name.
  void set_header(const std::string& name, const std::string& value) {
    for (auto& [k, v] : headers)
      if (strcasecmp(k.c_str(), name.c_str()) == 0) {
        v = value;
        return;
      }
    headers.emplace_back(name, value);
  }
};

Response json_response(const Reply& r) {
  Response out;
  out.status = r.status;
  out.body = r.text();
  out.headers = r.headers;
  return out;
}
Response error_response(int status, const std::string& message) {
  return json_response(error_reply(status, message));
}

// ---- connections -------------------------------------------------------------

// Per connection: where the guard is in the byte stream of its requests, and
// whether the connection is still there for a pool thread's answer.
struct PeerGuard {
  RequestFramer framer;     // the connection's bytes, cut into whole requests
  std::string handed_body;  // the body of the request being handed to the Router
  // Pistache 0.0.5 keys a queued write by the socket's descriptor, and closes
  // the descriptor when the client leaves; a write a pool thread queued as
  // the client left could meet that number given to the next connection
  // (seen: a file's bytes sent to the next client). A thread other than the
  // reactor's queues a write only holding send_mu with closed false, and the
  // reactor sets closed under send_mu before Pistache closes the socket: such
  // a write is queued before the close, as the reactor's own are, and goes
  // with the connection.
  std::recursive_mutex send_mu;
  bool closed = false;
  // Answers go out in the order their requests came (HTTP/1.1 pipelining):
  // while one is being answered off the reactor's turn (a pool task, a
  // file's later slices), the requests behind it wait here, each a closure
  // that answers it and says whether its answer is all queued (false: what
  // finishes it calls answered()).
  std::mutex order_mu;
  bool answering = false;
  std::deque<std::function<bool()>> waiting;
  // A refusal handed to Pistache and not yet written (refuse_in_turn): the
  // input that follows it nudges the writer (Handler::onInput).
  std::atomic<bool> refusal_queued{false};
};

std::shared_ptr<PeerGuard> guard_of(const std::shared_ptr<Tcp::Peer>& peer) {
  return peer ? std::static_pointer_cast<PeerGuard>(peer->tryGetData("collido-guard")) : nullptr;
}

// Whether a request may be answered now; if not, make_answer() makes the
// closure that answers it once the answers before it are out.
template <class MakeAnswer>
bool begin_answer(PeerGuard& g, MakeAnswer&& make_answer) {
  std::lock_guard<std::mutex> lock(g.order_mu);
  if (!g.answering) return g.answering = true;
  g.waiting.push_back(make_answer());
  return false;
}

// The answer being sent is all queued: the waiting requests are answered in
// order, here, until one goes on past this call (it calls answered() again).
void answered(PeerGuard& g) {
  for (;;) {
    std::function<bool()> next;
    {
      std::lock_guard<std::mutex> lock(g.order_mu);
      if (g.waiting.empty()) {
        g.answering = false;
        return;
      }
      next = std::move(g.waiting.front());
      g.waiting.pop_front();
    }
    if (!next()) return;
  }
}

// ---- files, with Range ------------------------------------------------------

Response file_response(const std::string& path, const Http::Request& req) {
  auto file = std::make_shared<OpenFile>();
  file->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  struct stat st {};
  if (file->fd < 0 || ::fstat(file->fd, &st) != 0 || !S_ISREG(st.st_mode))
    return error_response(404, "no such file");
  const uint64_t size = uint64_t(st.st_size);
  const FileValidators validators =
      file_validators(size, int64_t(st.st_mtim.tv_sec), int64_t(st.st_mtim.tv_nsec));
  auto header = [&](const char* name) {
    auto h = req.headers().tryGetRaw(name);
    return h ? h->value() : std::string();
  };
  Response out;
  out.mime = job::mime_type(path);
  out.headers.emplace_back("Accept-Ranges", "bytes");
  out.headers.emplace_back("Cache-Control", "private, max-age=60");
  // A browser revalidates what it cached (the UI's files at every load, a
  // video after a minute) and gets 304 instead of the file again.
  out.headers.emplace_back("ETag", validators.etag);
  out.headers.emplace_back("Last-Modified", http_date(validators.modified_s));
  if (not_modified(validators, header("If-None-Match"), header("If-Modified-Since"))) {
    out.status = 304;
    return out;
  }
  uint64_t first = 0, count = size;
  auto range_header = req.headers().tryGetRaw("Range");
  if (range_header && range_applies(validators, header("If-Range"))) {
    bool unsatisfiable = false;
    auto range = parse_range(range_header->value(), size, &unsatisfiable);
    if (unsatisfiable) {
      out.status = 416;
      out.mime = "application/json";
      out.body = error_reply(416, "the range starts beyond the file's " + std::to_string(size) +
                                      " bytes").body.dump();
      out.headers.emplace_back("Content-Range", "bytes */" + std::to_string(size));
      return out;
    }
    if (range) {
      first = range->first;
      count = range->second - range->first + 1;
      out.status = 206;
      out.headers.emplace_back("Content-Range", "bytes " + std::to_string(first) + "-" +
                                                    std::to_string(first + count - 1) + "/" +
                                                    std::to_string(size));
    }
  }
  out.file = FileBody{std::move(file), first, count};
  return out;
}

// Sends a file's part in slices of kSlice bytes, the next read when the last
// has left, so a download holds one slice in memory and the reactor thread
// reads one slice at a time between its other connections' work. Pistache's
// serveFile is not used: it answers only 200, and a download the viewer
// stops keeps its file open for the life of the process (0.0.5 closes the
// descriptor only once the whole file is sent; measured: 20 stopped
// downloads, 20 descriptors more). Here the sender, and its file, go when the
// connection does: the transport drops the queued write's promise, which
// holds the continuation, which holds the sender. A client that pipelines a
// second request behind a download would get its answer between two slices;
// no browser pipelines, and 0.0.5 drops a request that arrives in the same
// read as the one before it anyway.
class FileSender : public std::enable_shared_from_this<FileSender> {
 public:
  static constexpr uint64_t kSlice = 256 << 10;

  FileSender(std::string head, FileBody body, const std::shared_ptr<Tcp::Peer>& peer)
      : head_(std::move(head)), body_(std::move(body)), peer_(peer), guard_(guard_of(peer)) {}

  // Queues the first slice: true when that was the whole answer (or the
  // connection is gone), false when later slices follow, the last of which
  // (or what stops them) calls answered() for the requests behind it.
  bool start() { return send_next(true); }

 private:
  // On the reactor thread, or on a pool thread (the first slice of a pool
  // route's answer, and a slice whose write ended before its continuation
  // was attached).
  bool send_next(bool first) {
    auto peer = peer_.lock();
    if (!peer) return over(first);
    std::unique_lock<std::recursive_mutex> lock;
    if (guard_) {
      lock = std::unique_lock<std::recursive_mutex>(guard_->send_mu);
      if (guard_->closed) return over(first);
    }
    const uint64_t n = std::min(kSlice, body_.count - sent_);
    std::string slice = std::exchange(head_, {});  // the first slice carries the header
    const size_t offset = slice.size();
    slice.resize(offset + n);
    uint64_t got = 0;
    while (got < n) {
      const ssize_t r = ::pread(body_.file->fd, slice.data() + offset + got, n - got,
                                off_t(body_.first + sent_ + got));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) {
        // The file shrank under us (truncated in place, which our writers
        // never do): the promised length cannot be kept, so end the
        // connection rather than let the client read the next answer as body.
        ::shutdown(peer->fd(), SHUT_RDWR);
        return over(first);
      }
      got += uint64_t(r);
    }
    sent_ += n;
    const bool more = sent_ < body_.count;
    auto self = shared_from_this();
    const size_t length = slice.size();
    peer->send(RawBuffer(std::move(slice), length))
        .then(
            [self, more](ssize_t) {
              if (more) self->send_next(false);
            },
            [self, more](std::exception_ptr&) {
              if (more) self->over(false);  // no more slices: the answer ends here
            });
    return more ? false : over(first);
  }

  // The answer is over (all queued, or stopped). Its first slice tells the
  // caller; a later one lets the requests behind it go.
  bool over(bool first) {
    if (!first && guard_) answered(*guard_);
    return true;
  }

  std::string head_;
  FileBody body_;
  std::weak_ptr<Tcp::Peer> peer_;
  std::shared_ptr<PeerGuard> guard_;
  uint64_t sent_ = 0;
};

// ---- routes -----------------------------------------------------------------

// A query's count (limit=, an id): its digits, or dflt for anything else.
int64_t query_count(const std::string& s, int64_t dflt) {
  if (s.empty() || s.size() > 18 || !std::all_of(s.begin(), s.end(), ::isdigit)) return dflt;
  return std::stoll(s);
}

enum class Auth { kNone, kUser, kAdmin };

// Where a route's handler runs: on the reactor thread of its connection (a
// look-up, a page, a file), or on the request pool (work that computes: a
// password's hash, a mesh, a prediction; its connection's reactor serves the
// others meanwhile).
enum class Runs { kInline, kOnPool };

struct Route {
  std::string method;
  std::string pattern;
  Auth auth;
  std::function<Response(Request&)> handle;
  std::vector<std::string> parts;  // the pattern, split
  Runs runs = Runs::kInline;
};

// The pattern's parts match the path: literals equal, {name} takes one
// segment, {name*} the rest (one or more). Checked before anything is copied:
// every request is tried against the routes in turn.
bool match(const Route& r, Request& req) {
  const auto& p = r.parts;
  const auto& s = req.segments;
  auto is_rest = [](const std::string& part) {
    return part.size() > 3 && part.front() == '{' && part[part.size() - 2] == '*';
  };
  const bool rest = !p.empty() && is_rest(p.back());
  if (rest ? s.size() < p.size() : s.size() != p.size()) return false;
  for (size_t i = 0; i + (rest ? 1 : 0) < p.size(); ++i)
    if (p[i].front() != '{' && p[i] != s[i]) return false;
  std::map<std::string, std::string> params;
  for (size_t i = 0; i < p.size(); ++i) {
    const std::string& part = p[i];
    if (rest && i + 1 == p.size()) {
      std::string tail;
      for (size_t k = i; k < s.size(); ++k) tail += (k > i ? "/" : "") + s[k];
      params[part.substr(1, part.size() - 3)] = std::move(tail);
    } else if (part.front() == '{') {
      params[part.substr(1, part.size() - 2)] = s[i];
    }
  }
  req.params = std::move(params);
  return true;
}

std::optional<int64_t> id_param(const Request& req, const char* name) {
  const std::string& s = req.params.at(name);
  if (s.empty() || s.size() > 18 ||
      !std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); }))
    return std::nullopt;
  return std::stoll(s);
}

// Whether a JSON text nests arrays and objects deeper than `limit` (brackets
// inside strings do not count). nlohmann parses any depth without recursion,
// but copying or printing a value recurses: a body a few hundred thousand
// levels deep, well within the size limit, would overflow a thread's stack.
bool nests_deeper_than(const std::string& text, int limit) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : text) {
    if (in_string) {
      if (escaped) escaped = false;
      else if (c == '\\') escaped = true;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > limit) return true;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return false;
}

// The body as JSON, or the 400 that says why not.
std::optional<json> json_body(const Request& req, Response* error, bool allow_empty = false) {
  const std::string& body = req.body;
  if (body.empty() && allow_empty) return json(nullptr);
  // No document of this API nests past a handful of levels.
  constexpr int kMaxDepth = 64;
  if (nests_deeper_than(body, kMaxDepth)) {
    *error = error_response(400, "the body nests arrays and objects more than " +
                                     std::to_string(kMaxDepth) + " levels deep");
    return std::nullopt;
  }
  json j = json::parse(body, nullptr, false);
  if (j.is_discarded()) {
    *error = error_response(400, body.empty() ? "the request has no JSON body"
                                              : "the body is not valid JSON");
    return std::nullopt;
  }
  return j;
}

bool valid_token(const std::string& t) {
  return !t.empty() && t.size() <= 128 && std::all_of(t.begin(), t.end(), [](unsigned char c) {
    return std::isalnum(c) || c == '-' || c == '_';
  });
}

std::string share_page(const std::string& token, const Reply& info, bool embed) {
  const json& links = info.body["links"];
  const bool done = info.body.value("state", "") == "done";
  std::ostringstream h;
  const std::string t = html_escape(token);
  h << "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">"
       "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
       "<title>Collidoscope result</title>"
       "<link rel=\"alternate\" type=\"application/json+oembed\" href=\"/api/v1/oembed?url=/s/"
    << t << "\" title=\"Collidoscope result\">"
    << "<style>body{margin:0;font-family:system-ui,sans-serif;background:#111;color:#eee}"
       "main{max-width:960px;margin:auto;padding:"
    << (embed ? "0" : "1rem")
    << "}video,img{width:100%;height:auto;display:block}a{color:#8cf}</style></head><body><main>";
  if (!embed) h << "<h1>Collidoscope result</h1>";
  if (!done) {
    h << "<p>This result is not ready yet (" << html_escape(info.body.value("state", ""))
      << "). Reload the page in a moment.</p>";
  } else {
    h << "<video controls loop playsinline preload=\"metadata\" poster=\""
      << html_escape(links.value("poster", "")) << "\">";
    if (links.contains("webm"))
      h << "<source src=\"" << html_escape(links["webm"].get<std::string>()) << "\" type=\"video/webm\">";
    if (links.contains("mp4"))
      h << "<source src=\"" << html_escape(links["mp4"].get<std::string>()) << "\" type=\"video/mp4\">";
    if (links.contains("gif"))
      h << "<img src=\"" << html_escape(links["gif"].get<std::string>()) << "\" alt=\"collision animation\">";
    h << "</video>";
    if (!embed) {
      h << "<p>";
      for (const char* k : {"mp4", "webm", "gif", "poster", "stats", "manifest"})
        if (links.contains(k))
          h << "<a href=\"" << html_escape(links[k].get<std::string>()) << "\">" << k << "</a> ";
      h << "</p><p>Embed: <code>&lt;iframe src=\"/embed/" << t
        << "\" width=\"640\" height=\"360\"&gt;&lt;/iframe&gt;</code></p>";
    }
  }
  h << "</main></body></html>\n";
  return h.str();
}

// The session cookie's attributes: never read by scripts, never sent from
// another site, and over HTTPS only where the service is published on it.
std::string cookie_attributes(const JobService& svc) {
  const bool https = svc.public_url().compare(0, 8, "https://") == 0;
  return std::string("; Path=/; HttpOnly; SameSite=Strict") + (https ? "; Secure" : "");
}

std::vector<Route> make_routes(JobService* svc, const ServerOptions& opt) {
  std::vector<Route> r;
  auto adder = [&r](Runs runs) {
    return [&r, runs](const char* m, const char* p, Auth a, std::function<Response(Request&)> h) {
      r.push_back({m, p, a, std::move(h), split_path(p), runs});
    };
  };
  const auto add = adder(Runs::kInline);
  const auto add_on_pool = adder(Runs::kOnPool);  // a route whose work computes
  auto reply = [](Reply rep) { return json_response(rep); };

  add("GET", "/api/v1/health", Auth::kNone, [=](Request&) { return reply(svc->health()); });
  add("GET", "/api/v1/openapi.json", Auth::kNone, [](Request&) {
    Response out;
    out.body = openapi_document();
    return out;
  });
  add("GET", "/metrics", Auth::kNone, [=](Request&) {
    Response out;
    out.body = svc->metrics();
    out.mime = "text/plain; version=0.0.4";
    return out;
  });
  add_on_pool("POST", "/api/v1/accounts", Auth::kNone, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    return b ? reply(svc->create_account(*b)) : e;
  });
  add_on_pool("POST", "/api/v1/sessions", Auth::kNone, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    if (!b) return e;
    std::string token;
    Response out = reply(svc->create_session(*b, unix_now(), &token));
    if (!token.empty())
      out.headers.emplace_back(
          "Set-Cookie", std::string(kSessionCookie) + "=" + token + cookie_attributes(*svc) +
                            "; Max-Age=" + std::to_string(int64_t(svc->config().session_ttl_s)));
    return out;
  });
  add("DELETE", "/api/v1/sessions", Auth::kUser, [=](Request& q) {
    Response out = reply(svc->delete_session(q.token));
    out.headers.emplace_back("Set-Cookie", std::string(kSessionCookie) + "=" +
                                               cookie_attributes(*svc) + "; Max-Age=0");
    return out;
  });
  add("GET", "/api/v1/me", Auth::kUser, [](Request& q) {
    Reply rep;
    rep.body = {{"id", q.user->id}, {"name", q.user->name}, {"role", q.user->role}};
    return json_response(rep);
  });
  add("GET", "/api/v1/models", Auth::kUser, [=](Request& q) { return reply(svc->list_models(*q.user)); });
  add_on_pool("POST", "/api/v1/models", Auth::kUser, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    return b ? reply(svc->create_model(*q.user, *b)) : e;
  });
  add("GET", "/api/v1/models/{id}", Auth::kUser, [=](Request& q) {
    auto id = id_param(q, "id");
    return id ? reply(svc->get_model(*q.user, *id)) : error_response(404, "no such model");
  });
  add("DELETE", "/api/v1/models/{id}", Auth::kUser, [=](Request& q) {
    auto id = id_param(q, "id");
    return id ? reply(svc->delete_model(*q.user, *id)) : error_response(404, "no such model");
  });
  add_on_pool("PUT", "/api/v1/models/{id}/stl", Auth::kUser, [=](Request& q) {
    auto id = id_param(q, "id");
    return id ? reply(svc->upload_stl(*q.user, *id, q.body)) : error_response(404, "no such model");
  });
  add_on_pool("GET", "/api/v1/models/{id}/stl", Auth::kUser, [=](Request& q) {
    auto id = id_param(q, "id");
    if (!id) return error_response(404, "no such model");
    auto path = svc->model_stl_path(*q.user, *id);
    if (!path)
      return json_response(error_reply(http_status_of(path.status()), path.status().message()));
    return file_response(*path, *q.http);
  });
  add("GET", "/api/v1/algorithms", Auth::kNone, [=](Request&) { return reply(svc->algorithms()); });
  add_on_pool("POST", "/api/v1/predict", Auth::kUser, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    return b ? reply(svc->predict(*q.user, *b)) : e;
  });
  add_on_pool("POST", "/api/v1/start-preview", Auth::kUser, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    return b ? reply(svc->start_preview(*q.user, *b)) : e;
  });
  add_on_pool("POST", "/api/v1/jobs", Auth::kUser, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e);
    return b ? reply(svc->submit(*q.user, *b)) : e;
  });
  add("GET", "/api/v1/jobs", Auth::kUser, [=](Request& q) {
    return reply(svc->list_jobs(*q.user, size_t(query_count(q.query("limit"), kDefaultJobsAPage)),
                                q.query("before")));
  });
  add("GET", "/api/v1/jobs/{id}", Auth::kUser,
      [=](Request& q) { return reply(svc->get_job(*q.user, q.params["id"])); });
  add("DELETE", "/api/v1/jobs/{id}", Auth::kUser,
      [=](Request& q) { return reply(svc->delete_job(*q.user, q.params["id"])); });
  add("POST", "/api/v1/jobs/{id}/cancel", Auth::kUser,
      [=](Request& q) { return reply(svc->cancel_job(*q.user, q.params["id"])); });
  add("GET", "/api/v1/jobs/{id}/files/{path*}", Auth::kUser, [=](Request& q) {
    auto path = svc->job_file(*q.user, q.params["id"], q.params["path"]);
    return path ? file_response(*path, *q.http) : error_response(404, path.status().message());
  });
  add("POST", "/api/v1/jobs/{id}/shares", Auth::kUser, [=](Request& q) {
    Response e;
    auto b = json_body(q, &e, true);
    return b ? reply(svc->create_share(*q.user, q.params["id"], *b)) : e;
  });
  add("GET", "/api/v1/jobs/{id}/shares", Auth::kUser,
      [=](Request& q) { return reply(svc->list_shares(*q.user, q.params["id"])); });
  add("DELETE", "/api/v1/shares/{token}", Auth::kUser,
      [=](Request& q) { return reply(svc->delete_share(*q.user, q.params["token"])); });
  add("GET", "/api/v1/shares/{token}", Auth::kNone,
      [=](Request& q) { return reply(svc->share_info(q.params["token"])); });
  add("GET", "/api/v1/oembed", Auth::kNone, [=](Request& q) {
    // ?url=<public url>/s/<token>: the video as an oEmbed "video" with an iframe player.
    const std::string url = q.query("url");
    const auto at = url.rfind("/s/");
    const std::string token = at == std::string::npos ? "" : url.substr(at + 3);
    if (!valid_token(token)) return error_response(404, "url: not a share link of this server");
    Reply info = svc->share_info(token);
    if (info.status != 200) return json_response(info);
    const std::string base = svc->public_url();
    int width = 640, height = 360;
    if (auto mw = q.query("maxwidth"); !mw.empty() && std::all_of(mw.begin(), mw.end(), ::isdigit) &&
                                       mw.size() < 6)
      width = std::max(64, std::min(width, std::stoi(mw))), height = width * 9 / 16;
    Reply rep;
    rep.body = {{"version", "1.0"},
                {"type", "video"},
                {"provider_name", "Collidoscope"},
                {"provider_url", base + "/"},
                {"title", "Collidoscope result"},
                {"width", width},
                {"height", height},
                {"html", "<iframe src=\"" + base + "/embed/" + token + "\" width=\"" +
                             std::to_string(width) + "\" height=\"" + std::to_string(height) +
                             "\" frameborder=\"0\" allowfullscreen></iframe>"}};
    if (info.body["links"].contains("poster")) {
      rep.body["thumbnail_url"] = base + info.body["links"]["poster"].get<std::string>();
      rep.body["thumbnail_width"] = svc->config().render.width;
      rep.body["thumbnail_height"] = svc->config().render.height;
    }
    return json_response(rep);
  });
  auto page = [=](Request& q, bool embed) {
    const std::string token = q.params["token"];
    Reply info = valid_token(token) ? svc->share_info(token) : error_reply(404, "no such share");
    Response out;
    out.mime = "text/html; charset=utf-8";
    if (info.status != 200) {
      out.status = 404;
      out.body = "<!doctype html><title>Not found</title><p>This share link does not exist or "
                 "was revoked.</p>\n";
      return out;
    }
    out.body = share_page(token, info, embed);
    out.headers.emplace_back("Content-Security-Policy",
                             embed ? "default-src 'self'; style-src 'unsafe-inline'"
                                   : "default-src 'self'; style-src 'unsafe-inline'; frame-ancestors 'none'");
    return out;
  };
  add("GET", "/s/{token}", Auth::kNone, [=](Request& q) { return page(q, false); });
  add("GET", "/embed/{token}", Auth::kNone, [=](Request& q) { return page(q, true); });
  add("GET", "/s/{token}/{path*}", Auth::kNone, [=](Request& q) {
    auto path = svc->shared_file(q.params["token"], q.params["path"]);
    return path ? file_response(*path, *q.http) : error_response(404, "no such file");
  });
  add("GET", "/api/v1/admin/logs", Auth::kAdmin, [=](Request& q) {
    return reply(svc->admin_logs(*q.user, size_t(query_count(q.query("limit"), 100)),
                                 query_count(q.query("before"), 0)));
  });
  add("GET", "/api/v1/admin/predictor", Auth::kAdmin,
      [=](Request& q) { return reply(svc->admin_predictor(*q.user)); });
  add("POST", "/api/v1/admin/predictor/retrain", Auth::kAdmin,
      [=](Request& q) { return reply(svc->admin_retrain(*q.user)); });
  if (!opt.web_dir.empty()) {
    const std::string root = opt.web_dir;
    auto serve_static = [root](const std::string& rel, const Http::Request& http) {
      std::error_code ec;
      const fs::path base = fs::canonical(root, ec);
      if (ec) return error_response(404, "no such page");
      const fs::path full = fs::canonical(base / rel, ec);
      const std::string b = base.string() + "/";
      if (ec || full.string().compare(0, b.size(), b) != 0 || !fs::is_regular_file(full))
        return error_response(404, "no such page");
      // A library's gzip copy (scripts/install-web.sh makes them: three.js
      // goes from 2.1 MB to 0.4), unless the file changed after it was made.
      const std::string gz = full.string() + ".gz";
      auto accept = http.headers().tryGetRaw("Accept-Encoding");
      const bool gzip = accept && accepts_gzip(accept->value()) && fs::is_regular_file(gz, ec) &&
                        fs::last_write_time(gz, ec) >= fs::last_write_time(full, ec) && !ec;
      Response out = file_response(gzip ? gz : full.string(), http);
      if (out.status != 416) out.mime = web_mime_type(full.string());
      if (gzip && out.status != 416) out.set_header("Content-Encoding", "gzip");
      out.set_header("Vary", "Accept-Encoding");
      out.set_header("Cache-Control", "no-cache");  // revalidate: a new build shows at once
      return out;
    };
    add("GET", "/", Auth::kNone, [=](Request& q) { return serve_static("index.html", *q.http); });
    add("GET", "/ui/{path*}", Auth::kNone,
        [=](Request& q) { return serve_static(q.params["path"], *q.http); });
  }
  return r;
}

// ---- the request guard and the handler --------------------------------------

struct Shared {
  JobService* service = nullptr;
  ServerOptions options;
  std::vector<Route> routes;
  std::unique_ptr<RequestPool> pool;  // runs the routes that compute (Runs::kOnPool)
  uint64_t max_upload = 0;
};

// Pistache's own limit, which covers headers and body together: it sees heads
// alone (the guard holds each route to its body limit and keeps the body).
constexpr size_t kPistacheMaxRequest = 2 * RequestFramer::kMaxHeadBytes;

// Tcp::Handler::associateTransport is private (Transport is its friend); the
// inner handler below needs it. An explicit instantiation may name a private
// member (C++17 [temp.explicit]/14), which hands us a pointer to it.
using AssociateFn = void (Tcp::Handler::*)(Tcp::Transport*);
struct AssociateTag {
  friend AssociateFn associate_fn(AssociateTag);
};
template <AssociateFn F>
struct Expose {
  friend AssociateFn associate_fn(AssociateTag) { return F; }
};
template struct Expose<&Tcp::Handler::associateTransport>;

// A response header by name. Pistache 0.0.5 keeps headers added with
// addRaw() but writes only typed ones onto the wire, so every header of ours
// is a typed header of this one kind.
class NamedHeader : public Http::Header::Header {
 public:
  NamedHeader(std::string name, std::string value) : name_(std::move(name)), value_(std::move(value)) {}
  const char* name() const override { return name_.c_str(); }
  void write(std::ostream& os) const override { os << value_; }
#ifdef SAFE_HEADER_CAST
  uint64_t hash() const override { return std::hash<std::string>()(name_); }
#endif

 private:
  std::string name_, value_;
};

// Routes parsed requests (Pistache's parser, our routes).
class Router : public Http::Handler {
 public:
  HTTP_PROTOTYPE(Router)
  explicit Router(std::shared_ptr<const Shared> shared) : shared_(std::move(shared)) {}

  void onRequest(const Http::Request& http, Http::ResponseWriter writer) override {
    auto guard = guard_of(writer.peer());
    // The body the guard kept (it hands Pistache the head alone).
    std::string body = guard ? std::move(guard->handed_body) : std::string();
    // A request pipelined behind one still being answered waits for it.
    if (guard && !begin_answer(*guard, [&] {
          return later(http, std::move(writer), guard, std::move(body));
        }))
      return;
    // Most requests are answered here from the parser's request, with no
    // copies; one that goes to the pool is moved into holders.
    Dispatch d = dispatch(http);
    d.req.body = std::move(body);
    const bool done = answer(d, http, writer, guard.get(), shared_->pool.get(),
                             [&] { return shared_for(http, std::move(writer), guard); });
    if (done && guard) answered(*guard);
  }

 private:
  // The route that answers the request, its user authenticated; or, where
  // none does, the answer (404, 405, 401, 403).
  struct Dispatch {
    const Route* route = nullptr;
    Request req;
    Response answer;
  };

  // What an answer made after onRequest returns holds: the request (the
  // parser's, reassigned once onRequest returns, so moved out rather than
  // copied), the writer, the guard. The body is not in it: the guard keeps
  // bodies, and the Dispatch's Request carries the body.
  struct Held {
    std::shared_ptr<const Http::Request> request;
    std::shared_ptr<Http::ResponseWriter> out;
    std::shared_ptr<PeerGuard> guard;
  };
  static Held shared_for(const Http::Request& http, Http::ResponseWriter&& writer,
                         const std::shared_ptr<PeerGuard>& guard) {
    return {std::make_shared<const Http::Request>(std::move(const_cast<Http::Request&>(http))),
            std::make_shared<Http::ResponseWriter>(std::move(writer)), guard};
  }

  // A request that waits behind another: answered by the closure, which says
  // whether its answer is all queued.
  std::function<bool()> later(const Http::Request& http, Http::ResponseWriter&& writer,
                              const std::shared_ptr<PeerGuard>& guard, std::string&& body) {
    Held h = shared_for(http, std::move(writer), guard);
    auto d = std::make_shared<Dispatch>(dispatch(*h.request));
    d->req.body = std::move(body);
    return [shared = shared_, h, d]() -> bool {
      return answer(*d, *h.request, *h.out, h.guard.get(), shared->pool.get(), [&] { return h; });
    };
  }

  // Answers a dispatched request: dispatch's own answer or an inline route's
  // here, a route that computes on the pool, which needs the request and
  // writer held (hold() gives them). True when the answer is all queued;
  // false when a pool task or a file's later slices finish it (and call
  // answered()).
  template <class Hold>
  static bool answer(Dispatch& d, const Http::Request& http, Http::ResponseWriter& writer,
                     PeerGuard* guard, RequestPool* pool, Hold&& hold) {
    if (d.route && d.route->runs != Runs::kInline)
      return answer_on_pool(hold(), std::move(d), pool);
    const Response out = d.route ? run(*d.route, d.req) : std::move(d.answer);
    return respond_locked(http, writer, guard, out);
  }

  // Runs a route that computes on the pool: the task answers from the pool's
  // thread under the connection's send lock (PeerGuard); it points the
  // request's http at the held one. False when the task finishes the answer
  // (and calls answered()); true when it is answered here (503: the pool is full).
  static bool answer_on_pool(const Held& h, Dispatch d, RequestPool* pool) {
    auto task = [h, route = d.route, req = std::move(d.req)]() mutable {
      req.http = h.request.get();
      const Response answer = run(*route, req);
      RequestPool::answering();  // only the answer left: the next request finds the thread free
      if (respond_locked(*h.request, *h.out, h.guard.get(), answer) && h.guard) answered(*h.guard);
    };
    if (pool->submit(std::move(task))) return false;
    Response busy = error_response(503, "the server is busy; try again in a moment");
    busy.headers.emplace_back("Retry-After", "1");
    return respond_locked(*h.request, *h.out, h.guard.get(), busy);
  }

  // respond() holding the connection's send lock, unless the client has left
  // (then there is nobody to answer: true). Any thread.
  static bool respond_locked(const Http::Request& http, Http::ResponseWriter& writer,
                             PeerGuard* guard, const Response& out) {
    std::unique_lock<std::recursive_mutex> lock;
    if (guard) {
      lock = std::unique_lock<std::recursive_mutex>(guard->send_mu);
      if (guard->closed) return true;
    }
    try {
      return respond(http, writer, out);
    } catch (const std::exception&) {  // the peer went while the answer was written
      return true;
    }
  }

  // Sends the answer: on the reactor thread of its connection, or on a pool
  // thread holding the connection's send lock.
  // True when the answer is all queued (see FileSender::start).
  static bool respond(const Http::Request& http, Http::ResponseWriter& writer,
                      const Response& out) {
    // HTTP/1.1 keeps a connection open unless a side says "close"; 0.0.5
    // closes one that sent no Connection header, which costs every client
    // (wrk, curl, browsers' fetch) a new connection per request.
    const auto conn = http.headers().tryGet<Http::Header::Connection>();
    if (!conn && http.version() == Http::Version::Http11) {
      writer.headers().remove<Http::Header::Connection>();
      writer.headers().add<Http::Header::Connection>(Http::ConnectionControl::KeepAlive);
    }
    for (const auto& [k, v] : out.headers) writer.headers().add(std::make_shared<NamedHeader>(k, v));
    writer.headers().add(std::make_shared<NamedHeader>("X-Content-Type-Options", "nosniff"));
    // Pistache's MediaType knows a fixed set of top-level types; others
    // (model/stl) go out as a raw header.
    Http::Mime::MediaType mime;
    try {
      mime = Http::Mime::MediaType::fromString(out.mime);
    } catch (...) {
      writer.headers().add(std::make_shared<NamedHeader>("Content-Type", out.mime));
    }
    if (out.file || out.status == 304 || http.method() == Http::Method::Head)
      return send_head_and_file(http, writer, mime, out);
    writer.send(static_cast<Http::Code>(out.status), out.body.data(), out.body.size(), mime);
    return true;
  }

  static Response run(const Route& route, Request& req) {
    try {
      return route.handle(req);
    } catch (const std::exception& e) {  // a bug of ours: answer, do not kill the thread
      return error_response(500, std::string("internal error: ") + e.what());
    }
  }

  // The status line and headers as ResponseWriter::send writes them, then
  // the file's part through a FileSender; to a HEAD request, or as a 304, the
  // head alone.
  static bool send_head_and_file(const Http::Request& http, Http::ResponseWriter& writer,
                                 const Http::Mime::MediaType& mime, const Response& out) {
    if (mime.isValid()) writer.headers().add<Http::Header::ContentType>(mime);
    std::ostringstream head;
    const auto code = static_cast<Http::Code>(out.status);
    head << (http.version() == Http::Version::Http10 ? "HTTP/1.0 " : "HTTP/1.1 ") << out.status
         << ' ' << Http::codeString(code) << "\r\n";
    for (const auto& h : writer.headers().list()) {
      head << h->name() << ": ";
      h->write(head);
      head << "\r\n";
    }
    // A 304 has no content and says no length (RFC 9110 8.6).
    if (out.status != 304)
      head << "Content-Length: " << (out.file ? out.file->count : out.body.size()) << "\r\n";
    head << "\r\n";
    if (out.status == 304 || http.method() == Http::Method::Head) {
      std::string text = head.str();
      const size_t length = text.size();
      writer.peer()->send(RawBuffer(std::move(text), length));
      return true;
    }
    return std::make_shared<FileSender>(head.str(), *out.file, writer.peer())->start();
  }

  Dispatch dispatch(const Http::Request& http) {
    Dispatch d;
    auto answer = [&d](Response r) {
      d.answer = std::move(r);
      return std::move(d);
    };
    Request& req = d.req;
    req.http = &http;
    req.method = Http::methodString(http.method());
    bool ok = true;
    for (const std::string& part : split_path(http.resource())) {
      req.segments.push_back(percent_decode(part, &ok));
      if (!ok) return answer(error_response(404, "no such resource"));
    }
    // HEAD is GET without the body (RFC 9110 9.3.2): the GET route answers it
    // and onRequest sends the head alone.
    const std::string method = req.method == "HEAD" ? "GET" : req.method;
    std::string allowed;  // the path's methods, for a 405's Allow
    for (const Route& route : shared_->routes) {
      if (!match(route, req)) continue;
      if (allowed.find(route.method) == std::string::npos)
        allowed +=
            (allowed.empty() ? "" : ", ") + route.method + (route.method == "GET" ? ", HEAD" : "");
      if (route.method != method) continue;
      if (route.auth != Auth::kNone) {
        req.token = session_token(http);
        auto user = shared_->service->authenticate(req.token);
        if (!user) return answer(error_response(401, "sign in first (POST /api/v1/sessions)"));
        if (route.auth == Auth::kAdmin && user->role != "admin")
          return answer(error_response(403, "administrators only"));
        req.user = *user;
      }
      d.route = &route;
      return d;
    }
    if (!allowed.empty()) {
      Response out = error_response(405, "method " + req.method + " is not allowed here");
      out.set_header("Allow", allowed);
      return answer(std::move(out));
    }
    return answer(error_response(404, "no such resource"));
  }

  static std::string session_token(const Http::Request& http) {
    if (auto auth = http.headers().tryGet<Http::Header::Authorization>()) {
      const std::string v = auth->value();
      if (v.compare(0, 7, "Bearer ") == 0) return v.substr(7);
    }
    if (http.cookies().has(kSessionCookie)) return http.cookies().get(kSessionCookie).value;
    return {};
  }

  std::shared_ptr<const Shared> shared_;
};

// What the endpoint runs: reads each request's head as it arrives, refuses a
// body over its route's limit before anything holds it, keeps the body, and
// hands the Router (through Pistache's parser) the head of each whole request
// and the body beside it. (Http::Handler's onInput is private, so the
// guard cannot call it as a base; the Router is a second handler that shares
// this one's transport.)
class Handler : public Http::Handler {
 public:
  HTTP_PROTOTYPE(Handler)

  explicit Handler(std::shared_ptr<const Shared> shared)
      : shared_(shared), router_(std::make_shared<Router>(shared)) {
    router_->setMaxRequestSize(kPistacheMaxRequest);
  }
  // Each reactor thread gets a copy (Prototype::clone): with a Router of its own.
  Handler(const Handler& other) : Http::Handler(other), shared_(other.shared_),
        router_(std::make_shared<Router>(other.shared_)) {
    router_->setMaxRequestSize(kPistacheMaxRequest);
  }

  void onRequest(const Http::Request&, Http::ResponseWriter) override {}  // the Router answers

  void onConnection(const std::shared_ptr<Tcp::Peer>& peer) override {
    associate();
    static_cast<Tcp::Handler&>(*router_).onConnection(peer);
    peer->putData("collido-guard", std::make_shared<PeerGuard>());
  }

  void onInput(const char* buffer, size_t len, const std::shared_ptr<Tcp::Peer>& peer) override {
    associate();
    auto guard = std::static_pointer_cast<PeerGuard>(peer->tryGetData("collido-guard"));
    // onConnection gave it one; bytes that never passed the guard go nowhere.
    if (!guard) return;
    if (guard->framer.refused()) {  // after a refusal everything is dropped
      if (guard->refusal_queued) nudge_writer(peer);
      return;
    }
    std::vector<RequestFramer::Whole> whole;
    bool ask_continue = false;
    const RequestFramer::Refusal refusal =
        guard->framer.feed(buffer, len, &Handler::limit_for, this, &whole, &ask_continue);
    // One request a call: Pistache 0.0.5 parses one request a call and then
    // drops what is left of its buffer (pipelined requests that arrived
    // together went unanswered). Its body waits in the guard for the Router,
    // which takes it as Pistache hands over the parsed head; one Pistache
    // did not parse goes with the call.
    for (RequestFramer::Whole& w : whole) {
      guard->handed_body = std::move(w.body);
      static_cast<Tcp::Handler&>(*router_).onInput(w.head.data(), w.head.size(), peer);
      std::string().swap(guard->handed_body);
    }
    if (ask_continue) may_continue(*guard, peer);
    if (refusal.code) refuse_in_turn(guard, peer, refusal_text(refusal));
  }

  void onDisconnection(const std::shared_ptr<Tcp::Peer>& peer) override {
    if (auto guard = guard_of(peer)) {
      {
        std::lock_guard<std::recursive_mutex> lock(guard->send_mu);
        guard->closed = true;
      }
      // The requests still waiting have nobody to answer (and their closures
      // hold the guard: dropped here, not kept alive by it).
      std::deque<std::function<bool()>> dropped;
      std::lock_guard<std::mutex> lock(guard->order_mu);
      dropped.swap(guard->waiting);
    }
    static_cast<Tcp::Handler&>(*router_).onDisconnection(peer);
  }

 private:
  // Tells a client waiting to send its body to go on (curl waits a second
  // for this before an upload of over 1 MiB), unless an answer to an earlier
  // request of the connection is still to come: the interim answer would be
  // read as that request's. Then the client sends when its wait ends.
  static void may_continue(PeerGuard& g, const std::shared_ptr<Tcp::Peer>& peer) {
    {
      std::lock_guard<std::mutex> lock(g.order_mu);
      if (g.answering) return;
    }
    std::lock_guard<std::recursive_mutex> lock(g.send_mu);
    if (g.closed) return;
    static const std::string kContinue = "HTTP/1.1 100 Continue\r\n\r\n";
    try {
      std::string text = kContinue;
      peer->send(RawBuffer(std::move(text), kContinue.size()));
    } catch (const std::exception&) {  // the peer went as it was written
    }
  }

  // The largest body a request may carry: an STL upload's from a signed-in
  // user (checked here, before the body is buffered: anyone else would make
  // the server hold the upload limit a connection), else a JSON document's.
  // (The framer's Limit: context is the Handler.)
  static uint64_t limit_for(const RequestHead& h, const void* context) {
    const Shared& shared = *static_cast<const Handler*>(context)->shared_;
    const auto q = h.target.find('?');
    const auto parts = split_path(h.target.substr(0, q));
    if (h.method == "PUT" && parts.size() == 5 && parts[0] == "api" && parts[1] == "v1" &&
        parts[2] == "models" && parts[4] == "stl" && shared.service->authenticate(token_of(h)))
      return shared.max_upload;
    return shared.options.max_json_bytes;
  }
  // The session a request head names: its Bearer token, else its session cookie.
  static std::string token_of(const RequestHead& h) {
    if (!h.bearer.empty()) return h.bearer;
    const std::string key = std::string(kSessionCookie) + "=";
    size_t at = 0;
    while (at < h.cookies.size()) {
      size_t end = h.cookies.find(';', at);
      if (end == std::string::npos) end = h.cookies.size();
      std::string pair = h.cookies.substr(at, end - at);
      pair.erase(0, pair.find_first_not_of(' '));
      if (pair.compare(0, key.size(), key) == 0) return pair.substr(key.size());
      at = end + 1;
    }
    return {};
  }

  // Pistache 0.0.5 takes an event that finds a socket both readable and
  // writable as a read only (Transport::onReady tests isReadable, else
  // isWritable), and its epoll is edge-triggered: a write queued while the
  // client is still sending waits for an event without input. A refusal is
  // queued while its body is still coming, and once the client has sent it
  // and waits for the answer no event comes at all (seen: 3 in 800 runs of
  // BadInputGetsClearErrorsAndTheServerGoesOn, four at a time; curl timed out
  // with its 100 KiB sent and no byte back). An empty write queued after each
  // input arms the socket for writing again after that input was read, so the
  // event after the body's last bytes finds no input and the refusal goes out.
  static void nudge_writer(const std::shared_ptr<Tcp::Peer>& peer) {
    try {
      peer->send(RawBuffer(std::string(), 0)).then([](ssize_t) {}, [](std::exception_ptr&) {});
    } catch (const std::exception&) {  // the peer went as it was written
    }
  }

  // A refusal's answer (the connection closes after it).
  static std::string refusal_text(const RequestFramer::Refusal& r) {
    const std::string body = error_reply(r.code, r.message).body.dump() + "\n";
    return "HTTP/1.1 " + std::to_string(r.code) + " " + r.reason +
           "\r\nContent-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
           "\r\nConnection: close\r\n\r\n" + body;
  }

  // Sends a refusal in its request's turn (after the answers to the requests
  // before it, which may still be computing or going out in slices), then
  // closes the connection for writing once it is written.
  static void refuse_in_turn(const std::shared_ptr<PeerGuard>& guard,
                             const std::shared_ptr<Tcp::Peer>& peer, std::string msg) {
    std::weak_ptr<Tcp::Peer> weak = peer;
    auto send = [guard, weak, msg = std::move(msg)]() -> bool {
      std::lock_guard<std::recursive_mutex> lock(guard->send_mu);
      auto p = weak.lock();
      if (guard->closed || !p) return true;
      try {
        std::string text = msg;
        const size_t length = text.size();
        guard->refusal_queued = true;
        p->send(RawBuffer(std::move(text), length))
            .then(
                // On the reactor thread, the connection still there: its
                // descriptor is this client's.
                [guard, weak](ssize_t) {
                  guard->refusal_queued = false;
                  std::lock_guard<std::recursive_mutex> lock(guard->send_mu);
                  if (auto p = weak.lock(); p && !guard->closed) ::shutdown(p->fd(), SHUT_WR);
                },
                [guard](std::exception_ptr&) { guard->refusal_queued = false; });
      } catch (const std::exception&) {  // the peer went as it was written
      }
      return true;
    };
    if (begin_answer(*guard, [&] { return std::function<bool()>(send); })) {
      send();
      answered(*guard);
    }
  }

  void associate() {
    if (!associated_) {
      ((*router_).*associate_fn(AssociateTag{}))(transport());
      associated_ = true;
    }
  }

  std::shared_ptr<const Shared> shared_;
  std::shared_ptr<Router> router_;
  bool associated_ = false;
};

}  // namespace

std::vector<RouteInfo> route_table() {
  ServerOptions with_ui;
  with_ui.web_dir = "/";
  std::vector<RouteInfo> out;
  for (const Route& r : make_routes(nullptr, with_ui)) out.push_back({r.method, r.pattern});
  return out;
}

struct Server::Impl {
  std::shared_ptr<Shared> shared;
  std::unique_ptr<Http::Endpoint> endpoint;
  bool stopped = false;
};

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Server::~Server() { stop(); }

uint16_t Server::port() const { return uint16_t(impl_->endpoint->getPort()); }

void Server::stop() {
  if (impl_ && !impl_->stopped) {
    // The pool first: its tasks answer through the endpoint's transports.
    impl_->shared->pool->stop();
    impl_->endpoint->shutdown();
    impl_->stopped = true;
  }
}

Expected<std::unique_ptr<Server>> Server::start(JobService* service, const ServerOptions& options) {
  // A viewer who closes a video mid-download must not end the process: writes
  // to a closed socket give EPIPE instead of SIGPIPE (a process-wide setting a
  // socket server needs; nothing else of ours handles SIGPIPE).
  ::signal(SIGPIPE, SIG_IGN);
  if (options.threads < 1 || options.threads > 64) return invalid_argument("threads: in [1, 64]");
  if (options.work_threads < 1 || options.work_threads > 256)
    return invalid_argument("work threads: in [1, 256]");
  auto shared = std::make_shared<Shared>();
  shared->service = service;
  shared->options = options;
  shared->routes = make_routes(service, options);
  shared->max_upload = service->config().max_upload_bytes;
  shared->pool = std::make_unique<RequestPool>(options.work_threads, options.max_waiting_work);
  auto impl = std::make_unique<Impl>();
  impl->shared = shared;
  try {
    Address addr(options.host, Port(options.port));
    impl->endpoint = std::make_unique<Http::Endpoint>(addr);
    auto opts = Http::Endpoint::options()
                    .threads(options.threads)
                    // Close-on-exec: a child the service starts (sbatch, squeue) that
                    // outlived it would keep the port, and a restart could not listen.
                    .flags(Tcp::Options::ReuseAddr | Tcp::Options::CloseOnExec)
                    .maxRequestSize(kPistacheMaxRequest)
                    .maxResponseSize(size_t(1) << 30);
    impl->endpoint->init(opts);
    impl->endpoint->setHandler(std::make_shared<Handler>(shared));
    impl->endpoint->serveThreaded();
  } catch (const std::exception& e) {
    return io_error("cannot listen on " + options.host + ":" + std::to_string(options.port) + ": " +
                    e.what());
  }
  return std::unique_ptr<Server>(new Server(std::move(impl)));
}

}  // namespace collido::service
