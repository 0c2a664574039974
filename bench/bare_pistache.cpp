// The yardstick of bench/service_load.sh: a bare Pistache 0.0.5 endpoint with
// one handler that answers a constant, nothing else (no routing, no guard, no
// database). The service's routes are measured against it in the same run.
//
//   bare_pistache [THREADS]   prints "listening on PORT" (a free port), stops on SIGINT/SIGTERM
#include <pistache/endpoint.h>
#include <pistache/http.h>
#include <signal.h>

#include <cstdio>
#include <cstdlib>

using namespace Pistache;

class Constant : public Http::Handler {
 public:
  HTTP_PROTOTYPE(Constant)
  void onRequest(const Http::Request& req, Http::ResponseWriter writer) override {
    // Kept alive as the service keeps HTTP/1.1 connections (0.0.5 would close them).
    if (!req.headers().tryGet<Http::Header::Connection>()) {
      writer.headers().remove<Http::Header::Connection>();
      writer.headers().add<Http::Header::Connection>(Http::ConnectionControl::KeepAlive);
    }
    writer.send(Http::Code::Ok, "{\"status\":\"ok\"}\n", MIME(Application, Json));
  }
};

int main(int argc, char** argv) {
  const int threads = argc > 1 ? std::atoi(argv[1]) : 2;
  sigset_t stop;
  sigemptyset(&stop);
  sigaddset(&stop, SIGINT);
  sigaddset(&stop, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop, nullptr);  // the reactor threads inherit the mask
  ::signal(SIGPIPE, SIG_IGN);
  Http::Endpoint endpoint(Address("127.0.0.1", Port(0)));
  endpoint.init(Http::Endpoint::options().threads(threads).flags(Tcp::Options::ReuseAddr));
  endpoint.setHandler(Http::make_handler<Constant>());
  endpoint.serveThreaded();
  std::printf("listening on %u\n", unsigned(endpoint.getPort()));
  std::fflush(stdout);
  int sig = 0;
  sigwait(&stop, &sig);
  endpoint.shutdown();
  return 0;
}
