// The HTTP side of the service: Pistache 0.0.5's endpoint with our own route
// table (make_routes in http_server.cpp), request guard and file responses with Range. What 0.0.5
// does and how each part is met (DESIGN.md, "Service and storage"):
// - it buffers a request whole and reserves the declared Content-Length before
//   checking its limit: a guard reads each request's headers as they arrive
//   and answers 413 to a Content-Length over the route's limit (411 to a
//   chunked body) before Pistache's parser sees it;
// - its serveFile always answers 200 through sendfile() without MSG_NOSIGNAL,
//   and keeps the file open when the viewer stops a download: files are
//   answered here (200, 206, 416, Accept-Ranges), sent in slices from the
//   open file, and SIGPIPE is ignored for the whole process when the server
//   starts;
// - its Rest::Router may insert into a shared map from several threads: we
//   route ourselves, from a table that is never written after start-up;
// - it answers a request without a Connection header "Connection: Close":
//   an HTTP/1.1 request without one is kept alive, as HTTP/1.1 says;
// - it runs a handler on the reactor thread of its connection, which serves
//   no other connection meanwhile: the routes that compute run on a pool of
//   their own (request_pool.h) and answer from there.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/status.h"
#include "service/job_service.h"

namespace collido::service {

struct ServerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 8080;  // 0 = a free port (Server::port() tells which)
  int threads = 2;       // reactor threads
  // Threads for the requests that compute (sign-ins, uploads, model builds,
  // predictions, submissions), and how many may wait for one before the
  // server answers 503.
  int work_threads = 2;
  size_t max_waiting_work = 256;
  size_t max_json_bytes = 1 << 20;  // a JSON request body
  std::string web_dir;   // the browser UI's files ("" = none)
};

// One route of the API: what the OpenAPI document must describe.
struct RouteInfo {
  std::string method;   // "GET", "POST", ...
  std::string pattern;  // "/api/v1/jobs/{id}"; "{path*}" takes the rest of the path
};
// Every route the server answers, in the order they are matched.
std::vector<RouteInfo> route_table();
// The OpenAPI 3 document served at /api/v1/openapi.json.
const std::string& openapi_document();

class Server {
 public:
  // Listens and serves on background threads; the JobService must outlive it.
  static Expected<std::unique_ptr<Server>> start(JobService* service, const ServerOptions& options);
  ~Server();
  uint16_t port() const;
  void stop();

 private:
  struct Impl;
  explicit Server(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace collido::service
