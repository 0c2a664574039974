// `collidoscope serve`: the REST service (service/), and `collidoscope admin`,
// which makes the first administrator. Flags and printing only.
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <string>
#include <thread>

#include "app/cli.h"
#include "app/commands.h"
#include "service/http_server.h"
#include "service/job_service.h"

namespace collido::app {

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

std::string self_executable() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : p.string();
}

const std::vector<FlagSpec>& serve_flags() {
  static const std::vector<FlagSpec> flags = {
      {"host", true, "address to listen on (default 127.0.0.1)"},
      {"port", true, "port (default 8080; 0 = a free one, printed)"},
      {"data", true, "folder of the database, models and results (default var/)"},
      {"threads", true, "HTTP reactor threads (default 2)"},
      {"work-threads", true,
       "threads for the requests that compute: sign-ins, uploads, model builds, predictions, "
       "submissions (default 2)"},
      {"workers", true,
       "job workers (default: one per visible GPU, each job on its own; one without a GPU, a job "
       "taking every CPU)"},
      {"job-threads", true, "CPU threads per job (default: all it may use)"},
      {"max-upload-mb", true, "largest STL upload, MiB (default 64)"},
      {"max-queued", true, "queued jobs a user may have (default 8)"},
      {"memory-gb", true, "memory the jobs may use in all, GiB (default: this machine's)"},
      {"disk-reserve-gb", true,
       "disk kept free on the data folder's file system; a job whose predicted files would "
       "eat into it is refused (default 1)"},
      {"public-url", true, "base URL of share links (default http://HOST:PORT)"},
      {"web", true, "folder of the browser UI (default web/static when present)"},
      {"cost-model", true,
       "job cost model file(s), comma-separated (collidoscope gvm train on a job log); "
       "default: bench/data/job_model_cpu.json and job_model_cuda.json where present"},
      {"training-logs", true,
       "job logs a retrained cost model learns from besides the service's jobs, comma-separated; "
       "default with the default models: bench/data/jobs_cpu.csv and jobs_cuda.csv where present"},
      {"retrain-every", true,
       "finished jobs of a backend after which the cost model retrains (default 25; 0 = only "
       "when an administrator asks)"},
      {"executor", true,
       "where jobs run: local (worker processes here, the default) or slurm (sbatch to a "
       "cluster; docs/deploy.md)"},
      {"slurm-partition", true, "sbatch --partition of the jobs (default: the cluster's)"},
      {"slurm-account", true, "sbatch --account of the jobs"},
      {"slurm-gpus", false, "the nodes have GPUs: backend \"auto\" jobs run on CUDA"},
      {"slurm-gres", true, "sbatch --gres of a CUDA job (default gpu:1)"},
      {"slurm-cpus", true, "CPUs per job: --cpus-per-task and the job's threads (default 4)"},
      {"slurm-time-limit", true,
       "time limit of a job whose time is not predicted, minutes (default 60); a predicted one "
       "gets 2 x its 90th percentile + 5 min"},
      {"slurm-args", true, "more sbatch flags, space-separated (e.g. \"--qos=normal\")"},
      {"slurm-poll", true, "seconds between squeue calls (default 2)"},
      {"slurm-binary", true,
       "the collidoscope binary on the nodes (default: this one's path; the data folder must "
       "be at the same path there)"},
      {"demo", false, "start with the demo account and a demo job (make run)"},
      {"help", false, "this help"},
  };
  return flags;
}

}  // namespace

int cmd_serve(const Args& args) {
  const char* cmd = "serve";
  std::string error;
  auto parsed = parse_args(args, serve_flags(), &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help")) {
    print_help(
        "usage: collidoscope serve [--host 127.0.0.1] [--port 8080] [--data var/] [--demo] ...\n\n"
        "Serves the REST API (/api/v1, described at /api/v1/openapi.json), the result files\n"
        "and share links, and runs queued jobs in worker processes. Stops on SIGINT/SIGTERM;\n"
        "a job running then resumes from its checkpoint at the next start.\n"
        "The first administrator: `collidoscope admin create NAME` (password from\n"
        "COLLIDO_ADMIN_PASSWORD or standard input).",
        serve_flags());
    return kExitOk;
  }
  if (!parsed->positional().empty())
    return usage_error(cmd, "unexpected argument '" + parsed->positional()[0] + "'");
  const int64_t port = parsed->get_int("port", 8080, &error);
  const int64_t threads = parsed->get_int("threads", 2, &error);
  const int64_t work_threads = parsed->get_int("work-threads", 2, &error);
  const int64_t workers = parsed->get_int("workers", -1, &error);
  const int64_t job_threads = parsed->get_int("job-threads", 0, &error);
  const int64_t upload_mb = parsed->get_int("max-upload-mb", 64, &error);
  const int64_t max_queued = parsed->get_int("max-queued", 8, &error);
  const double memory_gb = parsed->get_double("memory-gb", 0, &error);
  const double disk_reserve_gb = parsed->get_double("disk-reserve-gb", 1, &error);
  const int64_t retrain_every = parsed->get_int("retrain-every", 25, &error);
  const int64_t slurm_cpus = parsed->get_int("slurm-cpus", 4, &error);
  const double slurm_minutes = parsed->get_double("slurm-time-limit", 60, &error);
  const double slurm_poll = parsed->get_double("slurm-poll", 2, &error);
  if (!error.empty()) return usage_error(cmd, error);
  const std::string executor = parsed->get("executor", "local");
  if (executor != "local" && executor != "slurm")
    return usage_error(cmd, "--executor must be local or slurm");
  if (slurm_cpus < 1 || slurm_cpus > 4096) return usage_error(cmd, "--slurm-cpus must be in 1..4096");
  if (!(slurm_minutes >= 1 && slurm_minutes <= 525600))
    return usage_error(cmd, "--slurm-time-limit must be in 1..525600 minutes");
  if (!(slurm_poll >= 0.1 && slurm_poll <= 3600))
    return usage_error(cmd, "--slurm-poll must be in 0.1..3600 seconds");
  if (retrain_every < 0 || retrain_every > 1000000)
    return usage_error(cmd, "--retrain-every must be in 0..1000000");
  if (port < 0 || port > 65535) return usage_error(cmd, "--port must be in 0..65535");
  if (threads < 1 || threads > 64) return usage_error(cmd, "--threads must be in 1..64");
  if (work_threads < 1 || work_threads > 256)
    return usage_error(cmd, "--work-threads must be in 1..256");
  if (workers < -1 || workers > 64) return usage_error(cmd, "--workers must be in 0..64");
  if (job_threads < 0 || job_threads > 4096) return usage_error(cmd, "--job-threads must be in 0..4096");
  if (upload_mb < 1 || upload_mb > 4096) return usage_error(cmd, "--max-upload-mb must be in 1..4096");
  if (max_queued < 1 || max_queued > 10000) return usage_error(cmd, "--max-queued must be in 1..10000");
  if (memory_gb < 0 || memory_gb > 1e6) return usage_error(cmd, "--memory-gb must be in [0, 1e6]");
  if (!(disk_reserve_gb >= 0 && disk_reserve_gb <= 1e6))
    return usage_error(cmd, "--disk-reserve-gb must be in [0, 1e6]");

  service::ServiceConfig config;
  config.data_dir = parsed->get("data", "var");
  config.job_executable = self_executable();
  config.workers = int(workers);
  config.job_threads = int(job_threads);
  config.max_upload_bytes = uint64_t(upload_mb) << 20;
  config.max_queued_per_user = int(max_queued);
  config.host_bytes = uint64_t(memory_gb * double(1ull << 30));
  config.disk_reserve_bytes = uint64_t(disk_reserve_gb * double(1ull << 30));
  config.retrain_every = int(retrain_every);
  config.executor = executor;
  config.slurm.partition = parsed->get("slurm-partition", "");
  config.slurm.account = parsed->get("slurm-account", "");
  config.slurm.gpus = parsed->has("slurm-gpus");
  config.slurm.gres = parsed->get("slurm-gres", "gpu:1");
  config.slurm.cpus = int(slurm_cpus);
  config.slurm.default_time_limit_s = slurm_minutes * 60;
  config.slurm.poll_s = slurm_poll;
  if (parsed->has("slurm-binary")) config.job_executable = parsed->get("slurm-binary", "");
  {
    std::istringstream words(parsed->get("slurm-args", ""));
    for (std::string w; words >> w;) config.slurm.extra_args.push_back(w);
  }
  if (executor == "slurm" && config.job_threads == 0) config.job_threads = config.slurm.cpus;
  auto file_list = [&](const char* flag) {
    std::vector<std::string> files;
    for (std::string& f : split_list(parsed->get(flag, "")))
      if (!f.empty()) files.push_back(std::move(f));
    return files;
  };
  if (parsed->has("cost-model")) {
    config.cost_models = file_list("cost-model");
    if (config.cost_models.empty()) return usage_error(cmd, "--cost-model: no file named");
  } else {
    // The committed models and the logs they were trained on, when serving from the
    // repository (make run).
    for (const char* f : {"bench/data/job_model_cpu.json", "bench/data/job_model_cuda.json"})
      if (std::filesystem::exists(f)) config.cost_models.push_back(f);
    for (const char* f : {"bench/data/jobs_cpu.csv", "bench/data/jobs_cuda.csv"})
      if (std::filesystem::exists(f)) config.training_logs.push_back(f);
  }
  if (parsed->has("training-logs")) {
    config.training_logs = file_list("training-logs");
    for (const std::string& f : config.training_logs)
      if (!std::filesystem::exists(f)) return usage_error(cmd, "--training-logs: no file " + f);
  }
  service::ServerOptions options;
  options.host = parsed->get("host", "127.0.0.1");
  options.port = uint16_t(port);
  options.threads = int(threads);
  options.work_threads = int(work_threads);
  options.web_dir = parsed->get("web", std::filesystem::exists("web/static/index.html") ? "web/static" : "");

  auto svc = service::JobService::open(config);
  if (!svc) {
    std::fprintf(stderr, "collidoscope serve: %s\n", svc.status().message().c_str());
    return exit_code(svc.status());
  }
  auto server = service::Server::start(svc->get(), options);
  if (!server) {
    std::fprintf(stderr, "collidoscope serve: %s\n", server.status().message().c_str());
    return exit_code(server.status());
  }
  const std::string url = "http://" + options.host + ":" + std::to_string((*server)->port());
  // Share links name the address people reach the service at.
  (*svc)->set_public_url(parsed->get("public-url", url));
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  if (Status st = (*svc)->start_workers(); !st) {
    std::fprintf(stderr, "collidoscope serve: %s\n", st.message().c_str());
    (*server)->stop();
    return exit_code(st);
  }
  std::printf("collidoscope: serving on %s  (API %s/api/v1, data in %s)\n", url.c_str(), url.c_str(),
              config.data_dir.c_str());
  if (executor == "slurm")
    std::printf("collidoscope: jobs go to Slurm (sbatch%s%s), %d CPUs each\n",
                config.slurm.partition.empty() ? "" : " --partition=",
                config.slurm.partition.c_str(), config.slurm.cpus);
  if (config.cost_models.empty())
    std::printf("collidoscope: no job cost model: time is not predicted (see --cost-model)\n");
  for (const std::string& m : config.cost_models)
    std::printf("collidoscope: jobs priced by %s\n", m.c_str());
  if (!config.cost_models.empty() && config.retrain_every > 0) {
    std::string logs;
    for (const std::string& l : config.training_logs) logs += (logs.empty() ? "" : ", ") + l;
    std::printf("collidoscope: the cost models retrain after every %d finished jobs of a backend, on "
                "the service's jobs%s%s\n",
                config.retrain_every, logs.empty() ? "" : " and ", logs.c_str());
  }
  if (parsed->has("demo")) {
    auto demo = (*svc)->start_demo();
    if (!demo) {
      std::fprintf(stderr, "collidoscope serve: demo: %s\n", demo.status().message().c_str());
    } else {
      std::printf("collidoscope: sign in as '%s' with password '%s' (kept in %s/demo-password)\n",
                  demo->name.c_str(), demo->password.c_str(), config.data_dir.c_str());
      std::printf("collidoscope: demo job %s (%s): %s/api/v1/jobs/%s\n", demo->job_id.c_str(),
                  demo->state.c_str(), url.c_str(), demo->job_id.c_str());
      if (!options.web_dir.empty()) std::printf("collidoscope: open %s/ in a browser\n", url.c_str());
    }
  }
  std::fflush(stdout);
  while (!g_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(200));
  std::printf("collidoscope: stopping (a running job resumes at the next start)\n");
  (*server)->stop();
  (*svc)->stop_workers();
  return kExitOk;
}

int cmd_admin(const Args& args) {
  const char* cmd = "admin";
  std::string error;
  static const std::vector<FlagSpec> flags = {
      {"data", true, "the service's data folder (default var/)"}, {"help", false, "this help"}};
  auto parsed = parse_args(args, flags, &error);
  if (!parsed) return usage_error(cmd, error);
  if (parsed->has("help") || parsed->positional().size() != 2 || parsed->positional()[0] != "create") {
    print_help(
        "usage: collidoscope admin create NAME [--data var/]\n\n"
        "Makes an administrator. The password comes from COLLIDO_ADMIN_PASSWORD, else the\n"
        "first line of standard input; there is no default password.",
        flags);
    return parsed->has("help") ? kExitOk : kExitUsage;
  }
  std::string password;
  if (const char* env = std::getenv("COLLIDO_ADMIN_PASSWORD")) password = env;
  else std::getline(std::cin, password);
  service::ServiceConfig config;
  config.data_dir = parsed->get("data", "var");
  auto svc = service::JobService::open(config);
  if (!svc) {
    std::fprintf(stderr, "collidoscope admin: %s\n", svc.status().message().c_str());
    return exit_code(svc.status());
  }
  if (Status st = (*svc)->create_admin(parsed->positional()[1], password); !st) {
    std::fprintf(stderr, "collidoscope admin: %s\n", st.message().c_str());
    return exit_code(st);
  }
  std::printf("administrator '%s' created\n", parsed->positional()[1].c_str());
  return kExitOk;
}

}  // namespace collido::app
