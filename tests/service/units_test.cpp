// The service's pieces without a server: the HTTP parts the server reads
// itself (request heads, header cleaning, Range, paths), GPU discovery, and
// what the store promises the executors.
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include "job/job.h"
#include "service/http_parse.h"
#include "service/job_service.h"
#include "service/request_pool.h"
#include "service/store.h"
#include "service/workers.h"
#include "tests/scratch.h"
#include "tests/stats_csv.h"

namespace collido::service {
namespace {

// The job `make run` starts shows collisions: its pour lands on wall1's floor
// and piles within its duration. (Poured from 60 m for 3 s, the demo showed a
// free fall that never touched anything.) The scene as the service submits it,
// run without its video.
TEST(Demo, ThePourLandsAndPilesWithinItsDuration) {
  job::JobSpec spec;
  spec.scene_json = JobService::demo_request().at("scene").dump();
  spec.out_dir = test::scratch_path("demo");
  spec.threads = 2;
  const job::JobResult r = job::run_job(spec, {});
  ASSERT_TRUE(r.status) << r.status.message();
  EXPECT_GT(r.cost.wall_contact_steps, 0);
  EXPECT_GT(r.cost.pair_contact_steps, 0);
  // The last frame: a pile on the floor (407 of the 1,500 touch it, 716 pairs
  // touch, some still bouncing), none lost.
  const test::StatsCsv stats = test::read_stats_csv(spec.out_dir);
  const size_t touching = stats.column("touching_wall"), pairs = stats.column("particle_contacts");
  ASSERT_TRUE(touching < stats.names.size() && pairs < stats.names.size() && !stats.rows.empty());
  EXPECT_GT(stats.rows.back()[touching], 300);
  EXPECT_GT(stats.rows.back()[pairs], 300);
  EXPECT_EQ(r.escaped, 0u);
}

TEST(HttpParse, RequestHeadsGiveTargetLengthAndChunked) {
  RequestHead h = parse_request_head("PUT /api/v1/models/3/stl?x=1 HTTP/1.1\r\nHost: a\r\ncontent-length:  684 ");
  EXPECT_EQ(h.target, "/api/v1/models/3/stl?x=1");
  EXPECT_EQ(h.content_length, 684u);
  EXPECT_FALSE(h.chunked);
  EXPECT_FALSE(h.bad_length);
  EXPECT_EQ(h.method, "PUT");
  EXPECT_TRUE(h.bearer.empty());
  // The session, as the guard reads it before a body is buffered.
  h = parse_request_head("PUT / HTTP/1.1\r\nAuthorization: Bearer abc-1\r\nCookie: a=1; collido_session=x_2");
  EXPECT_EQ(h.bearer, "abc-1");
  EXPECT_EQ(h.cookies, "a=1; collido_session=x_2");
  EXPECT_TRUE(parse_request_head("POST / HTTP/1.1\r\nTransfer-Encoding: gzip, Chunked").chunked);
  // Lengths two parsers could read differently are refused.
  for (const char* head :
       {"POST / HTTP/1.1\r\nContent-Length: 5\r\nContent-Length: 6",
        "POST / HTTP/1.1\r\nContent-Length: -1", "POST / HTTP/1.1\r\nContent-Length: 1e9",
        "POST / HTTP/1.1\r\nContent-Length: 99999999999999999999",
        "POST / HTTP/1.1\r\nContent-Length:", "POST / HTTP/1.1\nContent-Length: 5",
        "POST / HTTP/1.1\r\nX: a\rContent-Length: 5", "POST / HTTP/1.1\r\nContent-Length : 5",
        "POST / HTTP/1.1\r\nHost\t: x"})
    EXPECT_TRUE(parse_request_head(head).bad_length) << head;
  EXPECT_FALSE(parse_request_head("POST / HTTP/1.1\r\nContent-Length: 5\r\nContent-Length: 5").bad_length);
  // Expect: 100-continue, from an HTTP/1.1 client only.
  EXPECT_TRUE(parse_request_head("PUT /x HTTP/1.1\r\nExpect: 100-Continue").expects_continue);
  EXPECT_FALSE(parse_request_head("PUT /x HTTP/1.0\r\nExpect: 100-continue").expects_continue);
  EXPECT_FALSE(parse_request_head("PUT /x HTTP/1.1\r\nExpect: something").expects_continue);
  EXPECT_FALSE(parse_request_head("PUT /x HTTP/1.1").expects_continue);
}

// Pistache gets heads alone: the headers it cannot parse and Content-Length
// (the guard keeps the body) are dropped, the rest kept.
TEST(HttpParse, HeadersPistacheCannotParseAndTheLengthAreDroppedAndTheRestKept) {
  const std::string head =
      "PUT /api/v1/models/1/stl HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nContent-Type: model/stl\r\n"
      "Content-Length: 84\r\nX-Anything: model/stl";
  const std::string clean = head_for_pistache(head);
  EXPECT_EQ(clean.find("Content-Type"), std::string::npos) << clean;
  EXPECT_NE(clean.find("PUT /api/v1/models/1/stl HTTP/1.1\r\n"), std::string::npos);
  EXPECT_NE(clean.find("Host: 127.0.0.1:8080"), std::string::npos);
  EXPECT_EQ(clean.find("Content-Length"), std::string::npos) << clean;
  EXPECT_EQ(head_for_pistache("POST / HTTP/1.1\r\ncontent-length: 5\r\nHost: x"),
            "POST / HTTP/1.1\r\nHost: x");
  EXPECT_NE(clean.find("X-Anything: model/stl"), std::string::npos);  // not Pistache's to parse
  const std::string json_head = "POST / HTTP/1.1\r\nContent-Type: application/json";
  EXPECT_EQ(head_for_pistache(json_head), json_head);
}

// The guard's framing: a connection's pipelined requests come out whole and
// the same whatever the reads' boundaries (two reads split at every byte, and
// one byte a read), each head without its Content-Length, each body exact.
TEST(RequestFramer, CutsRequestsTheSameWhereverTheReadsEnd) {
  const std::string stream =
      "GET /a HTTP/1.1\r\nHost: x\r\n\r\n"
      "POST /b HTTP/1.1\r\nContent-Length: 10\r\n\r\n0123456789"
      "PUT /c HTTP/1.1\r\ncontent-length: 300\r\nExpect: 100-continue\r\n\r\n" +
      std::string(300, 'z') + "GET /d HTTP/1.1\r\n\r\n";
  const auto limit = [](const RequestHead&, const void*) -> uint64_t { return 1000; };
  using Whole = RequestFramer::Whole;
  const auto feed_in = [&](const std::vector<size_t>& cuts) {
    RequestFramer f;
    std::vector<Whole> all;
    size_t at = 0;
    for (size_t cut : cuts) {
      std::vector<Whole> got;
      bool ask = false;
      EXPECT_EQ(f.feed(stream.data() + at, cut - at, limit, nullptr, &got, &ask).code, 0);
      for (Whole& w : got) all.push_back(std::move(w));
      at = cut;
    }
    return all;
  };
  const std::vector<Whole> once = feed_in({stream.size()});
  ASSERT_EQ(once.size(), 4u);
  EXPECT_EQ(once[0].head, "GET /a HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(once[1].head, "POST /b HTTP/1.1\r\n\r\n");
  EXPECT_EQ(once[1].body, "0123456789");
  EXPECT_EQ(once[2].head.find("ength"), std::string::npos) << once[2].head;
  EXPECT_EQ(once[2].body, std::string(300, 'z'));
  EXPECT_EQ(once[3].head, "GET /d HTTP/1.1\r\n\r\n");
  EXPECT_TRUE(once[3].body.empty());
  const auto same = [&](const std::vector<Whole>& got, const std::string& how) {
    ASSERT_EQ(got.size(), once.size()) << how;
    for (size_t k = 0; k < got.size(); ++k) {
      EXPECT_EQ(got[k].head, once[k].head) << how;
      EXPECT_EQ(got[k].body, once[k].body) << how;
    }
  };
  for (size_t cut = 1; cut < stream.size(); ++cut)
    same(feed_in({cut, stream.size()}), "split at " + std::to_string(cut));
  std::vector<size_t> bytes;
  for (size_t k = 1; k <= stream.size(); ++k) bytes.push_back(k);
  same(feed_in(bytes), "a byte a read");
}

// A head over its limit, chunked, malformed or too long refuses its request
// and everything after it; the requests before it come out whole.
TEST(RequestFramer, ARefusedHeadEndsTheConnectionsRequests) {
  const auto limit = [](const RequestHead&, const void*) -> uint64_t { return 5; };
  const std::string ok = "GET /a HTTP/1.1\r\n\r\n";
  const struct {
    std::string head;
    int code;
  } cases[] = {{"POST /b HTTP/1.1\r\nContent-Length: 6\r\n\r\n", 413},
               {"POST /b HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 411},
               {"POST /b HTTP/1.1\r\nContent-Length: 5x\r\n\r\n", 400},
               {"GET /b HTTP/1.1\r\nX: " + std::string(RequestFramer::kMaxHeadBytes, 'a'), 431}};
  for (const auto& c : cases) {
    RequestFramer f;
    std::vector<RequestFramer::Whole> got;
    bool ask = false;
    const std::string bytes = ok + c.head + ok;
    EXPECT_EQ(f.feed(bytes.data(), bytes.size(), limit, nullptr, &got, &ask).code, c.code);
    EXPECT_TRUE(f.refused());
    ASSERT_EQ(got.size(), 1u) << c.code;
    EXPECT_EQ(got[0].head, ok);
    got.clear();
    EXPECT_EQ(f.feed(ok.data(), ok.size(), limit, nullptr, &got, &ask).code, 0);
    EXPECT_TRUE(got.empty()) << "nothing after a refusal";
  }
}

// Expect: 100-continue is passed on for a head whose body is still to come,
// first of its read; not when the body came with it or a request before it.
TEST(RequestFramer, AsksToContinueOnlyForTheFirstHeadStillWaitingForItsBody) {
  const auto limit = [](const RequestHead&, const void*) -> uint64_t { return 100; };
  const std::string asks = "PUT /m HTTP/1.1\r\nExpect: 100-continue\r\nContent-Length: 4\r\n\r\n";
  const auto ask_after = [&](const std::string& bytes) {
    RequestFramer f;
    std::vector<RequestFramer::Whole> got;
    bool ask = false;
    f.feed(bytes.data(), bytes.size(), limit, nullptr, &got, &ask);
    return ask;
  };
  EXPECT_TRUE(ask_after(asks));
  EXPECT_FALSE(ask_after(asks + "abcd"));
  EXPECT_FALSE(ask_after("GET / HTTP/1.1\r\n\r\n" + asks));
  EXPECT_FALSE(ask_after("PUT /m HTTP/1.1\r\nContent-Length: 4\r\n\r\n"));
}

TEST(HttpParse, RangesWithinTheFileOrWhole) {
  bool unsat = false;
  using R = std::pair<uint64_t, uint64_t>;
  EXPECT_EQ(parse_range("bytes=100-199", 1000, &unsat), R(100, 199));
  EXPECT_EQ(parse_range("bytes=100-", 1000, &unsat), R(100, 999));
  EXPECT_EQ(parse_range("bytes=900-5000", 1000, &unsat), R(900, 999));
  EXPECT_EQ(parse_range("bytes=-10", 1000, &unsat), R(990, 999));
  EXPECT_EQ(parse_range("bytes=-5000", 1000, &unsat), R(0, 999));
  EXPECT_FALSE(unsat);
  // Answered whole: absent, other units, several ranges, nonsense, reversed.
  for (const char* h : {"", "items=0-1", "bytes=0-1,5-6", "bytes=a-b", "bytes=5-1", "bytes=--1", "bytes=1"}) {
    EXPECT_FALSE(parse_range(h, 1000, &unsat)) << h;
    EXPECT_FALSE(unsat) << h;
  }
  // Beyond the end, or an empty suffix: 416.
  EXPECT_FALSE(parse_range("bytes=1000-", 1000, &unsat));
  EXPECT_TRUE(unsat);
  EXPECT_FALSE(parse_range("bytes=-0", 1000, &unsat));
  EXPECT_TRUE(unsat);
  EXPECT_FALSE(parse_range("bytes=0-", 0, &unsat));
  EXPECT_TRUE(unsat);
}

TEST(HttpParse, ConditionalRequestsOnAFilesTagAndDate) {
  // RFC 9110's example date, both ways; other formats and nonsense are not dates.
  EXPECT_EQ(http_date(784111777), "Sun, 06 Nov 1994 08:49:37 GMT");
  EXPECT_EQ(parse_http_date("Sun, 06 Nov 1994 08:49:37 GMT"), 784111777);
  for (const char* t : {"Sunday, 06-Nov-94 08:49:37 GMT", "Sun Nov  6 08:49:37 1994", "",
                        "Sun, 06 Nov 1994 08:49:37 UTC", "Sun, 32 Nov 1994 08:49:37 GMT",
                        "Sun, 06 Nov 1994 08:4x:37 GMT", "Xyz, 06 Nov 1994 08:49:37 GMT"})
    EXPECT_FALSE(parse_http_date(t)) << t;

  const FileValidators v = file_validators(1000, 784111777, 5);
  EXPECT_EQ(v.etag, "\"3e8-ae1b981bc490a05\"");
  EXPECT_NE(file_validators(1001, 784111777, 5).etag, v.etag);  // another size
  EXPECT_NE(file_validators(1000, 784111777, 6).etag, v.etag);  // rewritten in the same second
  // If-None-Match: any tag of the list, weakly; "*"; it decides over the date.
  EXPECT_TRUE(not_modified(v, v.etag, ""));
  EXPECT_TRUE(not_modified(v, "\"x\", W/" + v.etag, ""));
  EXPECT_TRUE(not_modified(v, "*", ""));
  EXPECT_FALSE(not_modified(v, "\"x\"", ""));
  EXPECT_FALSE(not_modified(v, "\"x\"", "Sun, 06 Nov 1994 08:49:37 GMT"));
  // If-Modified-Since: modified at or before the date; an unreadable date is ignored.
  EXPECT_TRUE(not_modified(v, "", "Sun, 06 Nov 1994 08:49:37 GMT"));
  EXPECT_TRUE(not_modified(v, "", "Mon, 07 Nov 1994 00:00:00 GMT"));
  EXPECT_FALSE(not_modified(v, "", "Sun, 06 Nov 1994 08:49:36 GMT"));
  EXPECT_FALSE(not_modified(v, "", "yesterday"));
  EXPECT_FALSE(not_modified(v, "", ""));
  // If-Range: the strong tag or the exact date, else the whole file.
  EXPECT_TRUE(range_applies(v, ""));
  EXPECT_TRUE(range_applies(v, v.etag));
  EXPECT_FALSE(range_applies(v, "W/" + v.etag));
  EXPECT_FALSE(range_applies(v, "\"x\""));
  EXPECT_TRUE(range_applies(v, "Sun, 06 Nov 1994 08:49:37 GMT"));
  EXPECT_FALSE(range_applies(v, "Sun, 06 Nov 1994 08:49:38 GMT"));
}

TEST(HttpParse, AcceptEncodingTakesGzipUnlessRefused) {
  for (const char* yes : {"gzip", "gzip, deflate, br, zstd", "br;q=1.0, GZIP;q=0.5", "*",
                          "deflate, *;q=0.1", " x-gzip ", "gzip;q=0.001"})
    EXPECT_TRUE(accepts_gzip(yes)) << yes;
  for (const char* no : {"", "identity", "br, deflate", "gzip;q=0", "gzip; q=0.000, *", "*;q=0",
                         "gzipx", "*;q=0, br"})
    EXPECT_FALSE(accepts_gzip(no)) << no;
}

TEST(HttpParse, PathsDecodeAndRefuseNul) {
  bool ok = true;
  EXPECT_EQ(percent_decode("%2e%2E", &ok), "..");
  EXPECT_TRUE(ok);
  percent_decode("%zz", &ok);
  EXPECT_FALSE(ok);
  ok = true;
  percent_decode("a%00b", &ok);
  EXPECT_FALSE(ok);
  ok = true;
  percent_decode("abc%4", &ok);
  EXPECT_FALSE(ok);
  EXPECT_EQ(split_path("//api/v1//jobs/"), (std::vector<std::string>{"api", "v1", "jobs"}));
  EXPECT_EQ(html_escape("<a href=\"x\">'&'</a>"), "&lt;a href=&quot;x&quot;&gt;&#39;&amp;&#39;&lt;/a&gt;");
  EXPECT_EQ(web_mime_type("js/app.js"), "text/javascript; charset=utf-8");
  EXPECT_EQ(web_mime_type("noext"), "application/octet-stream");
}

TEST(Workers, VisibleGpusFollowCudaVisibleDevices) {
  ::setenv("CUDA_VISIBLE_DEVICES", "2,0", 1);
  EXPECT_EQ(visible_gpus(), (std::vector<std::string>{"2", "0"}));
  ::setenv("CUDA_VISIBLE_DEVICES", "", 1);  // none: the CPU
  EXPECT_TRUE(visible_gpus().empty());
  ::unsetenv("CUDA_VISIBLE_DEVICES");
}

// A gate the tests' tasks wait at until it opens; every wait bounded.
class Gate {
 public:
  void open() {
    std::lock_guard<std::mutex> lock(mu_);
    open_ = true;
    cv_.notify_all();
  }
  bool wait() {
    std::unique_lock<std::mutex> lock(mu_);
    return cv_.wait_for(lock, std::chrono::seconds(30), [&] { return open_; });
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool open_ = false;
};

// The request pool runs every task it takes, takes one more than its free
// threads only while fewer than its limit wait, and answers what it took
// before it stops.
TEST(RequestPool, TakesWhatItsThreadsAndQueueHoldAndFinishesItBeforeStopping) {
  RequestPool pool(2, 1);
  Gate gate;
  std::atomic<int> ran{0};
  auto blocked = [&] {
    gate.wait();
    ++ran;
  };
  EXPECT_TRUE(pool.submit(blocked));
  EXPECT_TRUE(pool.submit(blocked));
  // Both threads busy (or about to be): one task may wait, the next is refused.
  EXPECT_TRUE(pool.submit(blocked));
  EXPECT_FALSE(pool.submit(blocked));
  EXPECT_EQ(pool.pending(), 3u);
  gate.open();
  for (int i = 0; i < 3000 && pool.pending() > 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(ran.load(), 3);
  EXPECT_EQ(pool.pending(), 0u);
  // With its threads free it takes as many at once as it has threads and queue.
  Gate second;
  for (int i = 0; i < 3; ++i)
    EXPECT_TRUE(pool.submit([&] {
      second.wait();
      ++ran;
    }));
  std::thread opener([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    second.open();
  });
  pool.stop();  // waits for the three
  opener.join();
  EXPECT_EQ(ran.load(), 6);
  EXPECT_FALSE(pool.submit([&] { ++ran; }));
  pool.stop();  // a second stop is harmless
  EXPECT_EQ(ran.load(), 6);
}

// A task that says it is answering frees its thread's place at once: with
// one thread and no queue, a request sent as the answer leaves is taken (it
// was refused while the thread was still leaving the task), and it runs once
// that thread is done.
TEST(RequestPool, ATaskThatIsAnsweringLeavesRoomForTheNext) {
  RequestPool pool(1, 0);
  Gate answered, sent;
  std::atomic<int> ran{0};
  ASSERT_TRUE(pool.submit([&] {
    RequestPool::answering();
    RequestPool::answering();  // a second call changes nothing
    answered.open();
    sent.wait();  // still writing its answer
    ++ran;
  }));
  answered.wait();
  EXPECT_EQ(pool.pending(), 0u);
  EXPECT_TRUE(pool.submit([&] { ++ran; }));
  EXPECT_FALSE(pool.submit([&] { ++ran; }));  // one waits for the thread, no more
  sent.open();
  pool.stop();
  EXPECT_EQ(ran.load(), 2);
  RequestPool::answering();  // off a pool thread: nothing
}

// A SQLite store in a fresh folder of its own (named for the test), removed
// when the test ends.
class ScratchStore {
 public:
  explicit ScratchStore(const std::string& name)
      : dir_(std::filesystem::temp_directory_path() / (name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    auto store = open_sqlite_store((dir_ / "db.sqlite").string());
    EXPECT_TRUE(store) << store.status().message();
    if (store) store_ = std::move(*store);
  }
  ~ScratchStore() {
    store_.reset();  // closed before its folder goes
    std::filesystem::remove_all(dir_);
  }
  Store* get() { return store_.get(); }

 private:
  std::filesystem::path dir_;
  std::unique_ptr<Store> store_;
};

// A user's job list in pages: newest first, ties in creation time by id, each
// page starting after the last one's place, none twice, another user's never.
TEST(Store, JobListPagesFollowOneAnotherWithoutGapsOrRepeats) {
  ScratchStore scratch("store_pages");
  ASSERT_NE(scratch.get(), nullptr);
  Store& st = *scratch.get();
  std::vector<std::string> expected;  // newest first
  const double times[] = {100.25, 100.5, 100.5, 100.5, 101, 99, 100.5};
  for (int k = 0; k < 7; ++k) {
    Job j;
    j.id = "job" + std::to_string(k);
    j.owner_id = 1;
    j.created_at = times[k];
    j.scene_json = j.prediction_json = j.cost_json = "{}";
    ASSERT_TRUE(st.insert_job(j));
    j.id = "other" + std::to_string(k);
    j.owner_id = 2;
    ASSERT_TRUE(st.insert_job(j));
  }
  expected = {"job4", "job6", "job3", "job2", "job1", "job0", "job5"};
  for (size_t page = 1; page <= 8; ++page) {
    std::vector<std::string> got;
    std::optional<JobCursor> after;
    while (true) {
      auto jobs = st.jobs_of(1, page, after);
      ASSERT_TRUE(jobs) << jobs.status().message();
      ASSERT_LE(jobs->size(), page);
      for (const Job& j : *jobs) got.push_back(j.id);
      if (jobs->size() < page) break;
      after = JobCursor{jobs->back().created_at, jobs->back().id};
      // The place survives its text form.
      const auto again = parse_job_cursor(job_cursor_text(*after));
      ASSERT_TRUE(again);
      EXPECT_EQ(again->created_at, after->created_at);
      EXPECT_EQ(again->id, after->id);
    }
    EXPECT_EQ(got, expected) << "pages of " << page;
  }
  for (const char* bad :
       {"", "zz", "0000000000000000", "00000000000000000x", "0000000000000000.a b",
        "7ff0000000000000.job1", "000000000000000g.job1", "0000000000000000.a/b"})
    EXPECT_FALSE(parse_job_cursor(bad)) << bad;
}

// The disk held by the queued jobs is theirs alone: a running or ended job's
// files are on the disk already.
TEST(Store, QueuedJobsHoldTheDiskTheyWereAdmittedBy) {
  ScratchStore scratch("store_disk");
  ASSERT_NE(scratch.get(), nullptr);
  Store& st = *scratch.get();
  EXPECT_EQ(*st.queued_output_bytes(), 0u);
  const std::pair<const char*, uint64_t> jobs[] = {{"queued", 3000}, {"queued", 40000}, {"running", 500000}, {"done", 6000000}};
  int k = 0;
  for (const auto& [state, bytes] : jobs) {
    Job j;
    j.id = "j" + std::to_string(k++);
    j.owner_id = 1;
    j.state = state;
    j.predicted_output_bytes = bytes;
    j.scene_json = j.prediction_json = j.cost_json = "{}";
    ASSERT_TRUE(st.insert_job(j));
  }
  EXPECT_EQ(*st.queued_output_bytes(), 43000u);
  EXPECT_EQ(st.job_by_id("j1")->predicted_output_bytes, 40000u);
}

// A restart requeues only local jobs (cluster jobs run on under their
// scheduler), and a job ends once however many executors end it.
TEST(Store, RestartsRequeueLocalJobsOnlyAndJobsEndOnce) {
  ScratchStore scratch("store_units");
  ASSERT_NE(scratch.get(), nullptr);
  Store& st = *scratch.get();
  for (const char* id : {"local", "cluster"}) {
    Job j;
    j.id = id;
    j.owner_id = 1;
    j.state = "running";
    j.scene_json = j.prediction_json = j.cost_json = "{}";
    ASSERT_TRUE(st.insert_job(j));
  }
  ASSERT_TRUE(st.set_job_executor_ref("cluster", "4711"));
  auto running = st.running_jobs();
  ASSERT_TRUE(running);
  ASSERT_EQ(running->size(), 2u);
  EXPECT_EQ(st.job_status("cluster")->executor_ref, "4711");
  auto requeued = st.requeue_running_jobs();
  ASSERT_TRUE(requeued);
  EXPECT_EQ(*requeued, std::vector<std::string>{"local"});
  EXPECT_EQ(st.job_by_id("cluster")->state, "running");
  LogRow row;
  row.job_id = "cluster";
  row.total_s = 3;
  auto first = st.finish_job("cluster", "done", "{}", "", 1.0, &row);
  row.total_s = 4;
  auto second = st.finish_job("cluster", "failed", "{}", "late", 2.0, &row);
  ASSERT_TRUE(first && second);
  EXPECT_TRUE(*first);
  EXPECT_FALSE(*second);  // another replica's end comes too late and changes nothing
  // The end's log row went in with it; the late one's did not.
  auto logs = st.logs(10, 0);
  ASSERT_TRUE(logs);
  ASSERT_EQ(logs->size(), 1u);
  EXPECT_EQ((*logs)[0].job_id, "cluster");
  EXPECT_EQ((*logs)[0].total_s, 3);
  EXPECT_EQ(st.job_by_id("cluster")->state, "done");
  EXPECT_EQ(st.job_by_id("cluster")->error, "");
  // An orphan (claimed, never given a Slurm id) goes to one replica of two
  // that saw it at the same start; a queued job or one with an id to none.
  Job orphan;
  orphan.id = "orphan";
  orphan.owner_id = 1;
  orphan.state = "running";
  orphan.started_at = 100;
  orphan.scene_json = orphan.prediction_json = orphan.cost_json = "{}";
  ASSERT_TRUE(st.insert_job(orphan));
  auto a = st.claim_orphan("orphan", 100, 200), b = st.claim_orphan("orphan", 100, 201);
  ASSERT_TRUE(a && b);
  EXPECT_TRUE(*a);
  EXPECT_FALSE(*b);
  EXPECT_EQ(st.job_by_id("orphan")->started_at, 200);
  EXPECT_FALSE(*st.claim_orphan("cluster", 0, 300));
  ASSERT_TRUE(st.set_job_executor_ref("orphan", "4712"));
  EXPECT_FALSE(*st.claim_orphan("orphan", 200, 300));
  // Deleting takes a job that is not running, and only such a one.
  auto running_delete = st.delete_job("orphan");
  ASSERT_TRUE(running_delete);
  EXPECT_FALSE(*running_delete);
  EXPECT_TRUE(st.job_by_id("orphan"));
  EXPECT_TRUE(*st.delete_job("local"));
  EXPECT_FALSE(st.job_by_id("local"));
}

}  // namespace
}  // namespace collido::service
