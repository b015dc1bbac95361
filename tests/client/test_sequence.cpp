// Reading a SemanticKITTI-layout sequence directory (what `sglc ingest DIR` ingests).
#include <gtest/gtest.h>

#include "client_test_util.hpp"
#include "sglc/client/sequence.hpp"

namespace sc = sglc::client;
using sglc::client::test::TempDir;
using sglc::client::test::writeFile;

namespace {

// DIR/velodyne/<frame>.bin and DIR/labels/<frame>.label (contents do not matter to openSequence).
std::string makeSequence(const TempDir& tmp, const std::string& name, const std::vector<int>& frames,
                         bool labels = true) {
  const auto dir = tmp.path() / name;
  std::filesystem::create_directories(dir / "velodyne");
  std::filesystem::create_directories(dir / "labels");
  for (int f : frames) {
    char stem[16];
    std::snprintf(stem, sizeof stem, "%06d", f);
    writeFile((dir / "velodyne" / (std::string(stem) + ".bin")).string(), "");
    if (labels) writeFile((dir / "labels" / (std::string(stem) + ".label")).string(), "");
  }
  return dir.string();
}

std::string poseLine(double x) {
  return "1 0 0 " + std::to_string(x) + " 0 1 0 0 0 0 1 0\n";
}

std::vector<std::int64_t> numbers(const sc::Sequence& s) {
  std::vector<std::int64_t> out;
  for (const auto& f : s.frames) out.push_back(f.number);
  return out;
}

}  // namespace

TEST(FrameRange, Parses) {
  auto r = sc::parseFrameRange("52:4501");
  EXPECT_EQ(*r.first, 52);
  EXPECT_EQ(*r.last, 4501);
  EXPECT_TRUE(r.contains(52));
  EXPECT_TRUE(r.contains(4501));
  EXPECT_FALSE(r.contains(4502));
  r = sc::parseFrameRange("000100:");
  EXPECT_EQ(*r.first, 100);
  EXPECT_FALSE(r.last);
  r = sc::parseFrameRange(":7");
  EXPECT_FALSE(r.first);
  EXPECT_EQ(*r.last, 7);
  r = sc::parseFrameRange("4501");
  EXPECT_TRUE(r.contains(4501));
  EXPECT_FALSE(r.contains(4500));
  for (const char* bad : {"", ":", "a:b", "5:3", "-1:4", "1:2:3", " 1:2", "1.5:2"})
    EXPECT_THROW(sc::parseFrameRange(bad), sglc::InputError) << "'" << bad << "'";
}

TEST(Sequence, ListsFramesInOrderAndNamesTheSessionAfterTheDirectory) {
  TempDir tmp;
  const auto dir = makeSequence(tmp, "07", {3, 1, 2, 10, 0});
  writeFile(tmp / "07/velodyne/notes.txt", "ignored");
  writeFile(tmp / "07/velodyne/abc.bin", "ignored: not a frame number");
  const auto s = sc::openSequence(dir + "/");
  EXPECT_EQ(s.name, "07");
  EXPECT_EQ(numbers(s), (std::vector<std::int64_t>{0, 1, 2, 3, 10}));
  EXPECT_EQ(s.frames[4].name, "000010");
  EXPECT_EQ(s.frames[4].label_path, dir + "/labels/000010.label");
  EXPECT_FALSE(s.has_poses);
  EXPECT_FALSE(s.frames[0].pose);
  EXPECT_FALSE(s.frames[0].stamp);
}

TEST(Sequence, RangeAndEverySelect) {
  TempDir tmp;
  const auto dir = makeSequence(tmp, "s", {0, 1, 2, 3, 4, 5, 6, 7, 8, 9});
  EXPECT_EQ(numbers(sc::openSequence(dir, sc::parseFrameRange("2:6"))), (std::vector<std::int64_t>{2, 3, 4, 5, 6}));
  EXPECT_EQ(numbers(sc::openSequence(dir, {}, 4)), (std::vector<std::int64_t>{0, 4, 8}));
  EXPECT_EQ(numbers(sc::openSequence(dir, sc::parseFrameRange("3:"), 3)), (std::vector<std::int64_t>{3, 6, 9}));
  EXPECT_THROW(sc::openSequence(dir, sc::parseFrameRange("20:30")), sglc::InputError);
  EXPECT_THROW(sc::openSequence(dir, {}, 0), sglc::InputError);
}

TEST(Sequence, PosesAndTimesByFrameNumberOrByPosition) {
  TempDir tmp;
  // By frame number: lines 0..5 for frames 2 and 5.
  const auto a = makeSequence(tmp, "a", {2, 5});
  std::string poses;
  for (int i = 0; i < 6; ++i) poses += poseLine(i);
  writeFile(a + "/poses.txt", poses);
  writeFile(a + "/times.txt", "0.0\n0.1\n0.2\n0.3\n0.4\n0.5\n");
  auto s = sc::openSequence(a);
  ASSERT_TRUE(s.has_poses && s.has_stamps);
  EXPECT_EQ((*s.frames[0].pose)(0, 3), 2.0);
  EXPECT_EQ((*s.frames[1].pose)(0, 3), 5.0);
  EXPECT_DOUBLE_EQ(*s.frames[1].stamp, 0.5);

  // By position: one line per scan present (a subset of a sequence with its poses).
  const auto b = makeSequence(tmp, "b", {52, 4501});
  writeFile(b + "/poses.txt", poseLine(100) + poseLine(200));
  s = sc::openSequence(b, sc::parseFrameRange("4501"));
  ASSERT_EQ(s.frames.size(), 1u);
  EXPECT_EQ((*s.frames[0].pose)(0, 3), 200.0);

  // Neither: an error naming the file.
  const auto c = makeSequence(tmp, "c", {1, 2, 9});
  writeFile(c + "/poses.txt", poseLine(0) + poseLine(1));
  try {
    sc::openSequence(c);
    FAIL() << "2 poses for 3 frames up to 9 accepted";
  } catch (const sglc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("poses.txt"), std::string::npos) << e.what();
  }
  const auto d = makeSequence(tmp, "d", {0});
  writeFile(d + "/times.txt", "zero\n");
  EXPECT_THROW(sc::openSequence(d), sglc::InputError);
}

TEST(Sequence, BadDirectoriesAreRejectedWithTheReason) {
  TempDir tmp;
  auto message = [](const std::string& dir) {
    try {
      sc::openSequence(dir);
    } catch (const sglc::InputError& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  EXPECT_NE(message(tmp / "missing").find("not a directory"), std::string::npos);
  std::filesystem::create_directories(tmp.path() / "novelo");
  EXPECT_NE(message(tmp / "novelo").find("velodyne"), std::string::npos);
  std::filesystem::create_directories(tmp.path() / "empty/velodyne");
  EXPECT_NE(message(tmp / "empty").find("no NNNNNN.bin"), std::string::npos);
  // Some scans labelled, one not: the missing file is named. None labelled: an unlabelled sequence.
  const auto partly = makeSequence(tmp, "partly", {4, 5});
  std::filesystem::remove(partly + "/labels/000004.label");
  EXPECT_NE(message(partly).find("000004.label"), std::string::npos);
  const auto nolabels = makeSequence(tmp, "nolabels", {4, 5}, false);
  const auto seq = sc::openSequence(nolabels);
  ASSERT_EQ(seq.frames.size(), 2u);
  EXPECT_TRUE(seq.frames[0].label_path.empty());
}

TEST(Sequence, RealSequenceDirectory) {
  if (!sglc::client::test::haveRealData()) GTEST_SKIP() << "real scans not found under " << sglc::client::test::sharedData();
  const auto s = sc::openSequence(sglc::client::test::sequence00());
  EXPECT_EQ(s.name, "00");
  EXPECT_EQ(numbers(s), (std::vector<std::int64_t>{52, 88, 850, 4501}));
}
