// The run-directory snapshot format (sim/snapshot.h): round trips and clear
// errors for every kind of damaged file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "sim/snapshot.h"

namespace collido::sim {
namespace {

namespace fs = std::filesystem;

class SnapshotIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("collido_snap_test_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  static Snapshot sample(size_t n) {
    Snapshot s;
    s.frame = 1234567890123ull;
    s.time = 0.125;
    s.origin = {1e6, -2.5e5, 3.25};  // far from the world origin on purpose
    s.resize(n);
    for (size_t i = 0; i < n; ++i) {
      s.x[i] = 0.5f * i, s.y[i] = -1.f * i, s.z[i] = 1e-3f * i;
      s.r[i] = 0.25f + 0.01f * i;
      s.vx[i] = 1.f, s.vy[i] = -2.f * i, s.vz[i] = 3.5f;
      s.contact[i] = i % 3 == 0;
    }
    return s;
  }

  static std::string bytes_of(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  static void put_bytes(const std::string& p, const std::string& b) {
    std::ofstream(p, std::ios::binary).write(b.data(), std::streamsize(b.size()));
  }
  // Reads p and expects an error whose message names the file and contains what.
  static void expect_error(const std::string& p, const std::string& what) {
    auto r = read_snapshot(p);
    ASSERT_FALSE(r) << "expected an error for " << p;
    EXPECT_NE(r.status().message().find(p), std::string::npos) << r.status().message();
    EXPECT_NE(r.status().message().find(what), std::string::npos) << r.status().message();
  }

  fs::path dir_;
};

TEST_F(SnapshotIoTest, RoundTripKeepsEveryField) {
  const Snapshot s = sample(37);
  const std::string p = path("a.snap");
  Status st = write_snapshot(p, s);
  ASSERT_TRUE(st) << st.message();
  EXPECT_EQ(fs::file_size(p), kSnapshotHeaderBytes + 37 * kSnapshotBytesPerParticle);
  auto r = read_snapshot(p);
  ASSERT_TRUE(r) << r.status().message();
  EXPECT_EQ(r->frame, s.frame);
  EXPECT_EQ(r->time, s.time);
  EXPECT_EQ(r->origin.x, s.origin.x);
  EXPECT_EQ(r->origin.y, s.origin.y);
  EXPECT_EQ(r->origin.z, s.origin.z);
  EXPECT_EQ(r->x, s.x);
  EXPECT_EQ(r->y, s.y);
  EXPECT_EQ(r->z, s.z);
  EXPECT_EQ(r->r, s.r);
  EXPECT_EQ(r->vx, s.vx);
  EXPECT_EQ(r->vy, s.vy);
  EXPECT_EQ(r->vz, s.vz);
  EXPECT_EQ(r->contact, s.contact);

  auto h = read_snapshot_header(p);
  ASSERT_TRUE(h) << h.status().message();
  EXPECT_EQ(h->frame, s.frame);
  EXPECT_EQ(h->size(), 0u);
}

TEST_F(SnapshotIoTest, LayoutIsTheDocumentedLittleEndianOne) {
  const std::string p = path("layout.snap");
  ASSERT_TRUE(write_snapshot(p, sample(2)));
  const std::string b = bytes_of(p);
  ASSERT_EQ(b.size(), 56u + 2 * 29);
  EXPECT_EQ(b.substr(0, 8), "CLSNAP01");
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    for (int k = 3; k >= 0; --k) v = (v << 8) | uint8_t(b[at + k]);
    return v;
  };
  EXPECT_EQ(u32(8), 1u);   // version
  EXPECT_EQ(u32(12), 2u);  // n
  double t;
  std::memcpy(&t, b.data() + 24, 8);
  EXPECT_EQ(t, 0.125);
  float x1;
  std::memcpy(&x1, b.data() + 56 + 4, 4);  // x[1]
  EXPECT_EQ(x1, 0.5f);
  EXPECT_EQ(uint8_t(b[56 + 2 * 28]), 1);  // contact[0]
  EXPECT_EQ(uint8_t(b[56 + 2 * 28 + 1]), 0);
}

TEST_F(SnapshotIoTest, EmptySnapshotRoundTrips) {
  const std::string p = path("empty.snap");
  ASSERT_TRUE(write_snapshot(p, sample(0)));
  auto r = read_snapshot(p);
  ASSERT_TRUE(r) << r.status().message();
  EXPECT_EQ(r->size(), 0u);
}

TEST_F(SnapshotIoTest, WriteLeavesNoTemporaryAndReplacesAtomically) {
  const std::string p = path("frame.snap");
  ASSERT_TRUE(write_snapshot(p, sample(5)));
  ASSERT_TRUE(write_snapshot(p, sample(9)));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()), 1);
  EXPECT_EQ(read_snapshot(p)->size(), 9u);
}

TEST_F(SnapshotIoTest, MismatchedArraysAreRefusedOnWrite) {
  Snapshot s = sample(4);
  s.vz.pop_back();
  EXPECT_FALSE(write_snapshot(path("bad.snap"), s));
  s = sample(4);
  s.contact.push_back(0);
  EXPECT_FALSE(write_snapshot(path("bad.snap"), s));
  EXPECT_FALSE(fs::exists(path("bad.snap")));
}

TEST_F(SnapshotIoTest, BadMagicIsNamed) {
  const std::string p = path("magic.snap");
  ASSERT_TRUE(write_snapshot(p, sample(3)));
  std::string b = bytes_of(p);
  b[0] = 'X';
  put_bytes(p, b);
  expect_error(p, "bad magic");
  put_bytes(p, "solid cube\nendsolid\n");  // short, and not ours
  expect_error(p, "bad magic");
}

TEST_F(SnapshotIoTest, TruncatedFileIsNamed) {
  const std::string p = path("cut.snap");
  ASSERT_TRUE(write_snapshot(p, sample(10)));
  std::string b = bytes_of(p);
  put_bytes(p, b.substr(0, b.size() - 1));
  expect_error(p, "truncated");
  put_bytes(p, b.substr(0, 20));
  expect_error(p, "truncated");
  put_bytes(p, "");
  expect_error(p, "truncated");
}

TEST_F(SnapshotIoTest, AbsurdCountIsRejectedWithoutAllocating) {
  const std::string p = path("huge.snap");
  ASSERT_TRUE(write_snapshot(p, sample(1)));
  std::string b = bytes_of(p);
  for (int k = 0; k < 4; ++k) b[12 + k] = char(0xff);  // n = 4294967295
  put_bytes(p, b);
  expect_error(p, "implausible");
  for (int k = 0; k < 4; ++k) b[12 + k] = 0;
  b[12] = 100;  // n = 100 but the file holds 1
  put_bytes(p, b);
  expect_error(p, "truncated");
}

TEST_F(SnapshotIoTest, TrailingBytesAndVersionAreChecked) {
  const std::string p = path("extra.snap");
  ASSERT_TRUE(write_snapshot(p, sample(2)));
  std::string b = bytes_of(p);
  put_bytes(p, b + "xx");
  expect_error(p, "trailing");
  b[8] = 2;  // version 2
  put_bytes(p, b);
  expect_error(p, "version 2");
}

TEST_F(SnapshotIoTest, NonFiniteAndNegativeValuesAreRejected) {
  const std::string p = path("nan.snap");
  Snapshot s = sample(3);
  s.vy[2] = std::numeric_limits<float>::quiet_NaN();
  ASSERT_TRUE(write_snapshot(p, s));
  expect_error(p, "vy of particle 2");
  s = sample(3);
  s.r[1] = -1.f;
  ASSERT_TRUE(write_snapshot(p, s));
  expect_error(p, "radius of particle 1");
  s = sample(3);
  s.contact[0] = 7;
  ASSERT_TRUE(write_snapshot(p, s));
  expect_error(p, "contact flag");
}

TEST_F(SnapshotIoTest, MissingFileIsAnIoError) {
  auto r = read_snapshot(path("nope.snap"));
  ASSERT_FALSE(r);
  EXPECT_EQ(r.status().code(), ErrorCode::kIo);
  EXPECT_NE(r.status().message().find("nope.snap"), std::string::npos);
}

TEST(SnapshotPathTest, SixDigitsThenMore) {
  EXPECT_EQ(snapshot_path("run", 42), "run/frames/frame_000042.snap");
  EXPECT_EQ(snapshot_path("run", 1234567), "run/frames/frame_1234567.snap");
}

}  // namespace
}  // namespace collido::sim
