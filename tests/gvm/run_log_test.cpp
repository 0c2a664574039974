// The run-log CSV: round trips and the errors a hand-edited or truncated file gives.
#include "gvm/run_log.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>

#include "gvm/evaluate.h"
#include "tests/scratch.h"

namespace collido::gvm {
namespace {

const char* kHeader =
    "particles,triangles,triangles_original,radius,wall_area,wall_box_volume,method,traversal,"
    "frames,backend,device,threads,time_per_frame_s,total_time_s,peak_host_bytes,peak_device_bytes,gpu_load\n";

bool same_bits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

void expect_equal(const RunRecord& a, const RunRecord& b) {
  EXPECT_EQ(a.config.particles, b.config.particles);
  EXPECT_EQ(a.config.triangles, b.config.triangles);
  EXPECT_EQ(a.config.triangles_original, b.config.triangles_original);
  EXPECT_TRUE(same_bits(a.config.radius, b.config.radius));
  EXPECT_TRUE(same_bits(a.config.wall_area, b.config.wall_area));
  EXPECT_TRUE(same_bits(a.config.wall_box_volume, b.config.wall_box_volume));
  EXPECT_EQ(a.config.method, b.config.method);
  EXPECT_EQ(a.config.traversal, b.config.traversal);
  EXPECT_EQ(a.config.frames, b.config.frames);
  EXPECT_EQ(a.config.backend, b.config.backend);
  EXPECT_EQ(a.config.device, b.config.device);
  EXPECT_EQ(a.config.threads, b.config.threads);
  EXPECT_TRUE(same_bits(a.measure.time_per_frame_s, b.measure.time_per_frame_s));
  EXPECT_TRUE(same_bits(a.measure.total_time_s, b.measure.total_time_s));
  EXPECT_TRUE(same_bits(a.measure.peak_host_bytes, b.measure.peak_host_bytes));
  EXPECT_TRUE(same_bits(a.measure.peak_device_bytes, b.measure.peak_device_bytes));
  EXPECT_TRUE(same_bits(a.measure.gpu_load, b.measure.gpu_load));
}

// Parses text expected to fail and returns the message.
std::string error_of(const std::string& text) {
  auto r = parse_run_log(text);
  EXPECT_FALSE(r) << "parsed: " << text;
  return r ? "" : r.status().message();
}

const char* kGoodRow =
    "1000,226056,156,1.5,9e4,1.1e6,gravity,particle,10,cuda,NVIDIA H100,8,0.0123,0.5,1e8,2e9,"
    "0.75\n";

TEST(RunLog, RoundTripKeepsEveryFieldExactly) {
  auto rows = synthetic_run_log(50, 4);
  rows[0].config.device = "GPU \"big\", rev 2";  // quotes and a comma need CSV quoting
  rows[1].config.device = "";
  rows[2].config.method = Method::kReference;
  rows[2].measure.time_per_frame_s = 0.1;  // not exactly representable in binary
  rows[3].config.radius = 0.1;
  rows[3].config.wall_area = 1.0 / 3.0;
  auto back = parse_run_log(format_run_log(rows));
  ASSERT_TRUE(back) << back.status().message();
  ASSERT_EQ(back->size(), rows.size());
  for (size_t i = 0; i < rows.size(); ++i) expect_equal(rows[i], (*back)[i]);
}

TEST(RunLog, FileRoundTrip) {
  const std::string path = test::scratch_path("gvm_run_log_test.csv");
  auto rows = synthetic_run_log(10, 5);
  ASSERT_TRUE(write_run_log(path, rows));
  auto back = read_run_log(path);
  ASSERT_TRUE(back) << back.status().message();
  ASSERT_EQ(back->size(), 10u);
  for (size_t i = 0; i < rows.size(); ++i) expect_equal(rows[i], (*back)[i]);
  auto missing = read_run_log(path + ".absent");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.status().code(), ErrorCode::kNotFound);  // bad input, not an I/O failure
}

TEST(RunLog, HeaderNamesEveryColumnInOrder) {
  std::string header;
  for (const auto& c : run_log_columns()) header += (header.empty() ? "" : ",") + c;
  EXPECT_EQ(header + "\n", kHeader);
  EXPECT_EQ(format_run_log({}), kHeader);
}

TEST(RunLog, AcceptsAnyColumnOrderExtraColumnsCrlfAndBlankLines) {
  const std::string text =
      "job_id,gpu_load,peak_device_bytes,peak_host_bytes,total_time_s,time_per_frame_s,"
      "threads,device,backend,frames,traversal,method,wall_box_volume,wall_area,radius,"
      "triangles_original,triangles,particles\r\n"
      "\r\n"
      "j7,0.5,100,200,3.5,0.25,4,cpu0,cpu,14,wall,bin,8000,600,0.25,12,12,1e6\r\n"
      "\n";
  auto rows = parse_run_log(text);
  ASSERT_TRUE(rows) << rows.status().message();
  ASSERT_EQ(rows->size(), 1u);
  const RunRecord& r = (*rows)[0];
  EXPECT_EQ(r.config.particles, 1000000);
  EXPECT_EQ(r.config.method, Method::kBin);
  EXPECT_EQ(r.config.traversal, Traversal::kWall);
  EXPECT_EQ(r.config.device, "cpu0");
  EXPECT_EQ(r.config.frames, 14);
  EXPECT_EQ(r.measure.gpu_load, 0.5);
  EXPECT_EQ(r.measure.time_per_frame_s, 0.25);
  EXPECT_EQ(r.config.radius, 0.25);
  EXPECT_EQ(r.config.wall_area, 600.0);
  EXPECT_EQ(r.config.wall_box_volume, 8000.0);
}

TEST(RunLog, BadValueNamesLineAndColumn) {
  const std::string bad_frames =
      std::string(kHeader) + kGoodRow +
      "1000,226056,156,1.5,9e4,1.1e6,gravity,particle,ten,cuda,NVIDIA H100,8,0.0123,0.5,1e8,2e9,"
      "0.75\n";
  const std::string msg = error_of(bad_frames);
  EXPECT_NE(msg.find("line 3, column 9 (frames)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'ten'"), std::string::npos) << msg;

  const std::string m2 =
      error_of(std::string(kHeader) + "1000,226056,156,1.5,9e4,1.1e6,voronoi,particle,10,cuda,X,8,1,1,1,1,0.5\n");
  EXPECT_NE(m2.find("line 2, column 7 (method)"), std::string::npos) << m2;

  const std::string m3 =
      error_of(std::string(kHeader) + "1000,226056,156,1.5,9e4,1.1e6,bin,particle,10,cuda,X,8,1,1,1,1,1.5\n");
  EXPECT_NE(m3.find("column 17 (gpu_load)"), std::string::npos) << m3;

  const std::string m4 =
      error_of(std::string(kHeader) + "0,226056,156,1.5,9e4,1.1e6,bin,particle,10,cuda,X,8,1,1,1,1,0.5\n");
  EXPECT_NE(m4.find("column 1 (particles)"), std::string::npos) << m4;

  const std::string m5 =
      error_of(std::string(kHeader) + "10,20,20,1.5,9e4,1.1e6,bin,particle,10,gpu,X,8,1,1,1,1,0.5\n");
  EXPECT_NE(m5.find("column 10 (backend)"), std::string::npos) << m5;

  const std::string m6 =
      error_of(std::string(kHeader) + "10,20,20,1.5,9e4,1.1e6,bin,particle,10,cpu,X,8,-1,1,1,1,0.5\n");
  EXPECT_NE(m6.find("column 13 (time_per_frame_s)"), std::string::npos) << m6;

  const std::string m7 =
      error_of(std::string(kHeader) + "10,20,20,1.5,9e4,1.1e6,bin,particle,10,cpu,X,8,nan,1,1,1,0.5\n");
  EXPECT_NE(m7.find("column 13"), std::string::npos) << m7;

  // Geometry must be positive: a radius or area of 0 makes the ratios meaningless.
  const std::string m8 = error_of(std::string(kHeader) +
                                  "10,20,20,0,9e4,1.1e6,bin,particle,10,cpu,X,8,1,1,1,1,0.5\n");
  EXPECT_NE(m8.find("line 2, column 4 (radius): expected a finite number > 0, got '0'"),
            std::string::npos)
      << m8;
  const std::string m9 = error_of(std::string(kHeader) +
                                  "10,20,20,1,9e4,-5,bin,particle,10,cpu,X,8,1,1,1,1,0.5\n");
  EXPECT_NE(m9.find("column 6 (wall_box_volume)"), std::string::npos) << m9;
}

TEST(RunLog, StructuralErrorsNameTheLine) {
  EXPECT_NE(error_of("").find("line 1"), std::string::npos);
  const std::string missing = error_of("particles,triangles\n1,2\n");
  EXPECT_NE(missing.find("missing column 'triangles_original'"), std::string::npos) << missing;
  const std::string dup = error_of("particles,particles\n");
  EXPECT_NE(dup.find("line 1, column 2: duplicate column 'particles'"), std::string::npos) << dup;
  const std::string short_row = error_of(std::string(kHeader) + kGoodRow + kGoodRow + "1,2,3\n");
  EXPECT_NE(short_row.find("line 4: 3 fields, the header has 17"), std::string::npos) << short_row;
  const std::string open_quote = error_of(std::string(kHeader) + "1,2,3,\"bin\n");
  EXPECT_NE(open_quote.find("line 2, column 4: unterminated quote"), std::string::npos)
      << open_quote;
  const std::string stray = error_of(std::string(kHeader) + "1,2,3,b\"in,");
  EXPECT_NE(stray.find("line 2, column 4: quote inside an unquoted field"), std::string::npos)
      << stray;
  const std::string after = error_of(std::string(kHeader) + "1,2,3,\"bin\"x,");
  EXPECT_NE(after.find("line 2"), std::string::npos) << after;
}

// Two passes of one sweep become one row per configuration, combined as calibrate's
// repeats are; a configuration that differs in any input stays a row of its own.
TEST(RunLog, MergeRepeatsKeepsFastestTimesAndLargestMemory) {
  auto rows = synthetic_run_log(6, 4);
  std::vector<RunRecord> second = rows;
  second[0].measure.time_per_frame_s *= 0.5;  // faster per frame,
  second[0].measure.total_time_s *= 2.0;      // slower in total,
  second[0].measure.gpu_load = 0.5;           // (whose load must not be taken)
  second[0].measure.peak_host_bytes *= 1.1;   // a larger peak
  second[1].measure.total_time_s *= 0.5;      // faster in total, with its load
  second[1].measure.gpu_load = 0.25;
  second[2].config.frames += 1;  // another configuration
  std::vector<RunRecord> both = rows;
  both.insert(both.end(), second.begin(), second.end());
  const auto merged = merge_repeats(both);
  ASSERT_EQ(merged.size(), rows.size() + 1);
  EXPECT_EQ(merged[0].measure.time_per_frame_s, second[0].measure.time_per_frame_s);
  EXPECT_EQ(merged[0].measure.total_time_s, rows[0].measure.total_time_s);
  EXPECT_EQ(merged[0].measure.gpu_load, rows[0].measure.gpu_load);
  EXPECT_EQ(merged[0].measure.peak_host_bytes, second[0].measure.peak_host_bytes);
  EXPECT_EQ(merged[1].measure.total_time_s, second[1].measure.total_time_s);
  EXPECT_EQ(merged[1].measure.gpu_load, 0.25);
  EXPECT_EQ(merged[1].measure.time_per_frame_s, rows[1].measure.time_per_frame_s);
  for (size_t i = 3; i < rows.size(); ++i) expect_equal(merged[i], rows[i]);
  expect_equal(merged.back(), second[2]);
}

TEST(RunLog, ValidateNamesTheField) {
  RunConfig c;
  c.particles = 10;
  c.triangles = 10;
  c.triangles_original = 10;
  EXPECT_TRUE(validate(c));
  c.wall_area = 0;
  EXPECT_NE(validate(c).message().find("wall_area"), std::string::npos);
  c.wall_area = 1;
  c.radius = std::nan("");
  EXPECT_NE(validate(c).message().find("radius"), std::string::npos);
  c.radius = 1;
  c.frames = 0;
  EXPECT_NE(validate(c).message().find("frames"), std::string::npos);
  RunMeasure m;
  EXPECT_TRUE(validate(m));
  m.gpu_load = 2.0;
  EXPECT_NE(validate(m).message().find("gpu_load"), std::string::npos);
}

}  // namespace
}  // namespace collido::gvm
