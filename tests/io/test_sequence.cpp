// Reading a SemanticKITTI-layout sequence directory (what `sglc ingest DIR` ingests).
#include <gtest/gtest.h>

#include <fstream>
#include <functional>

#include "sglc/io.hpp"
#include "sglc/sequence.hpp"
#include "test_util.hpp"

using sglc::test::TempDir;

namespace {

void writeFile(const std::string& path, const std::string& text) { std::ofstream(path, std::ios::binary) << text; }

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

std::string poseLine(double x) { return "1 0 0 " + std::to_string(x) + " 0 1 0 0 0 0 1 0\n"; }

std::vector<std::int64_t> numbers(const sglc::Sequence& s) {
  std::vector<std::int64_t> out;
  for (const auto& f : s.frames) out.push_back(f.number);
  return out;
}

}  // namespace

TEST(Sequence, ListsFramesInOrderAndNamesTheSessionAfterTheDirectory) {
  TempDir tmp;
  const auto dir = makeSequence(tmp, "07", {3, 1, 2, 10, 0});
  writeFile(tmp.file("07/velodyne/notes.txt"), "ignored");
  writeFile(tmp.file("07/velodyne/abc.bin"), "ignored: not a frame number");
  const auto s = sglc::openSequence(dir + "/");
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
  EXPECT_EQ(numbers(sglc::openSequence(dir, sglc::FrameSelection::parse("2:6"))),
            (std::vector<std::int64_t>{2, 3, 4, 5}));
  EXPECT_EQ(numbers(sglc::openSequence(dir, sglc::FrameSelection::parse("1:8:3,9"))),
            (std::vector<std::int64_t>{1, 4, 7, 9}));
  EXPECT_EQ(numbers(sglc::openSequence(dir, {}, 4)), (std::vector<std::int64_t>{0, 4, 8}));
  EXPECT_EQ(numbers(sglc::openSequence(dir, sglc::FrameSelection::parse("3:"), 3)),
            (std::vector<std::int64_t>{3, 6, 9}));
  EXPECT_THROW(sglc::openSequence(dir, sglc::FrameSelection::parse("20:30")), sglc::InputError);
  EXPECT_THROW(sglc::openSequence(dir, {}, 0), sglc::InputError);
}

TEST(Sequence, PosesAndTimesByFrameNumberOrByPosition) {
  TempDir tmp;
  // By frame number: lines 0..5 for frames 2 and 5.
  const auto a = makeSequence(tmp, "a", {2, 5});
  std::string poses;
  for (int i = 0; i < 6; ++i) poses += poseLine(i);
  writeFile(a + "/poses.txt", poses);
  writeFile(a + "/times.txt", "0.0\n0.1\n0.2\n0.3\n0.4\n0.5\n");
  auto s = sglc::openSequence(a);
  ASSERT_TRUE(s.has_poses && s.has_stamps);
  EXPECT_EQ((*s.frames[0].pose)(0, 3), 2.0);
  EXPECT_EQ((*s.frames[1].pose)(0, 3), 5.0);
  EXPECT_DOUBLE_EQ(*s.frames[1].stamp, 0.5);

  // By position: one line per scan present (a subset of a sequence with its poses).
  const auto b = makeSequence(tmp, "b", {52, 4501});
  writeFile(b + "/poses.txt", poseLine(100) + poseLine(200));
  s = sglc::openSequence(b, sglc::FrameSelection::parse("4501"));
  ASSERT_EQ(s.frames.size(), 1u);
  EXPECT_EQ((*s.frames[0].pose)(0, 3), 200.0);

  // Neither: an error naming the file.
  const auto c = makeSequence(tmp, "c", {1, 2, 9});
  writeFile(c + "/poses.txt", poseLine(0) + poseLine(1));
  try {
    sglc::openSequence(c);
    FAIL() << "2 poses for 3 frames up to 9 accepted";
  } catch (const sglc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("poses.txt"), std::string::npos) << e.what();
  }
  const auto d = makeSequence(tmp, "d", {0});
  writeFile(d + "/times.txt", "zero\n");
  EXPECT_THROW(sglc::openSequence(d), sglc::InputError);
}

TEST(Sequence, BadDirectoriesAreRejectedWithTheReason) {
  TempDir tmp;
  auto message = [](const std::string& dir) {
    try {
      sglc::openSequence(dir);
    } catch (const sglc::InputError& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  EXPECT_NE(message(tmp.file("missing")).find("not a directory"), std::string::npos);
  std::filesystem::create_directories(tmp.path() / "novelo");
  EXPECT_NE(message(tmp.file("novelo")).find("velodyne"), std::string::npos);
  std::filesystem::create_directories(tmp.path() / "empty/velodyne");
  EXPECT_NE(message(tmp.file("empty")).find("no NNNNNN scans"), std::string::npos);
  // Some scans labelled, one not: the missing file is named. None labelled: an unlabelled sequence.
  const auto partly = makeSequence(tmp, "partly", {4, 5});
  std::filesystem::remove(partly + "/labels/000004.label");
  EXPECT_NE(message(partly).find("000004.label"), std::string::npos);
  const auto nolabels = makeSequence(tmp, "nolabels", {4, 5}, false);
  const auto seq = sglc::openSequence(nolabels);
  ASSERT_EQ(seq.frames.size(), 2u);
  EXPECT_TRUE(seq.frames[0].label_path.empty());
}

TEST(Sequence, RealSequenceDirectory) {
  SGLC_REQUIRE_REAL_DATA();
  const auto s = sglc::openSequence(sglc::test::scansDir() + "/sequences/00");
  EXPECT_EQ(s.name, "00");
  EXPECT_EQ(numbers(s), (std::vector<std::int64_t>{52, 88, 850, 4501}));
}

TEST(Sequence, AnyOneScanFormatAndLabelsAsNpy) {
  TempDir tmp;
  const auto dir = tmp.path() / "pcd";
  std::filesystem::create_directories(dir / "velodyne");
  std::filesystem::create_directories(dir / "labels");
  for (const char* stem : {"000000", "000001"}) {
    writeFile((dir / "velodyne" / (std::string(stem) + ".pcd")).string(), "");
    writeFile((dir / "labels" / (std::string(stem) + ".npy")).string(), "");
  }
  writeFile((dir / "velodyne" / "README.txt").string(), "ignored");
  const sglc::Sequence s = sglc::openSequence(dir.string());
  ASSERT_EQ(s.frames.size(), 2u);
  EXPECT_EQ(s.frames[1].scan_path, (dir / "velodyne" / "000001.pcd").string());
  EXPECT_EQ(s.frames[1].label_path, (dir / "labels" / "000001.npy").string());

  // PCD files without labels/: the files' own label fields (or the labeller) give the labels.
  std::filesystem::remove_all(dir / "labels");
  EXPECT_TRUE(sglc::openSequence(dir.string()).frames[0].label_path.empty());

  writeFile((dir / "velodyne" / "000002.bin").string(), "");
  try {
    sglc::openSequence(dir.string());
    ADD_FAILURE() << "mixed formats accepted";
  } catch (const sglc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("one format"), std::string::npos) << e.what();
  }
}

TEST(Sequence, TumPosesGiveStampsAndPoses) {
  TempDir tmp;
  const std::string dir = makeSequence(tmp, "tum", {0, 1, 2}, false);
  // t tx ty tz qx qy qz qw; frame 1 is turned 90 degrees about z.
  writeFile(dir + "/poses.txt",
            "# timestamp tx ty tz qx qy qz qw\n"
            "100.5 0 0 0 0 0 0 1\n100.6 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n100.7 2 0 0 0 0 0 1\n");
  const sglc::Sequence s = sglc::openSequence(dir);
  ASSERT_TRUE(s.has_poses && s.has_stamps);
  EXPECT_DOUBLE_EQ(*s.frames[1].stamp, 100.6);
  EXPECT_NEAR((*s.frames[1].pose)(0, 3), 1.0, 1e-12);
  EXPECT_NEAR((*s.frames[1].pose)(1, 0), 1.0, 1e-9);  // x axis turned onto y
  // times.txt wins over the TUM stamps.
  writeFile(dir + "/times.txt", "# seconds\n0\n0.1\n0.2\n");  // comments as in every other line-based file
  EXPECT_DOUBLE_EQ(*sglc::openSequence(dir).frames[1].stamp, 0.1);
  writeFile(dir + "/poses.txt", "1 2 3 4 5\n");
  try {
    sglc::openSequence(dir);
    ADD_FAILURE() << "5-column poses accepted";
  } catch (const sglc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected 12 (KITTI 3x4) or 8 (TUM"), std::string::npos) << e.what();
  }
  writeFile(dir + "/poses.txt", "0 0 0 0 0 0 0 2\n0 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n");
  EXPECT_THROW(sglc::openSequence(dir), sglc::InputError);  // quaternion norm 2
}

TEST(Sequence, TumPosesWriteAndReadBack) {
  TempDir tmp;
  sglc::Mat4d T = sglc::Mat4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(10.25, -3, 0.5);
  sglc::writeTumPoses(tmp.file("t.txt"), {{1234567890.123456, T}});
  const auto back = sglc::readTumPoses(tmp.file("t.txt"));
  ASSERT_EQ(back.size(), 1u);
  EXPECT_NEAR(back[0].stamp, 1234567890.123456, 1e-6);
  EXPECT_TRUE(back[0].pose.isApprox(T, 1e-8));
}

namespace {

// KITTI 00's calib.txt Tr (velodyne -> left camera).
const char* const kKittiTr =
    "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 "
    "8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 "
    "-7.206933692422e-03 -2.921968648686e-01\n";

// A camera driving forward (its z) 2 m per frame, as KITTI's poses.txt gives it.
std::string cameraPoses(int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += "1 0 0 0 0 1 0 0 0 0 1 " + std::to_string(2.0 * i) + "\n";
  return out;
}

std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const sglc::InputError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace

TEST(Sequence, KittiCameraPosesNextToCalibBecomeLidarPoses) {
  TempDir tmp;
  const std::string dir = makeSequence(tmp, "kitti", {0, 1, 2, 3}, false);
  writeFile(dir + "/poses.txt", cameraPoses(4));
  writeFile(dir + "/calib.txt", std::string("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n") + kKittiTr);
  const sglc::Sequence s = sglc::openSequence(dir);
  ASSERT_TRUE(s.has_poses);
  EXPECT_TRUE(s.poses_from_camera);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings.front();
  // The LiDAR drives along its own x: 6 m after three frames, within the calibration's small tilt.
  const Eigen::Vector3d t = s.frames[3].pose->topRightCorner<3, 1>();
  EXPECT_NEAR(t.x(), 6.0, 0.01);
  EXPECT_NEAR(t.y(), 0.0, 0.1);
  EXPECT_NEAR(t.z(), 0.0, 0.1);
  EXPECT_TRUE(s.frames[0].pose->isApprox(sglc::Mat4d::Identity(), 1e-9));

  // Told they are LiDAR poses, they pass unchanged, and the motion along z is pointed out.
  const sglc::Sequence as_is = sglc::openSequence(dir, {}, 1, {"", sglc::PosesFrame::kLidar});
  EXPECT_FALSE(as_is.poses_from_camera);
  EXPECT_NEAR((*as_is.frames[3].pose)(2, 3), 6.0, 1e-12);
  ASSERT_EQ(as_is.warnings.size(), 1u);
  EXPECT_NE(as_is.warnings[0].find("along the sensor's z"), std::string::npos) << as_is.warnings[0];
  EXPECT_NE(as_is.warnings[0].find("poses.txt"), std::string::npos) << as_is.warnings[0];
}

TEST(Sequence, PosesFrameErrorsNameWhatIsMissing) {
  TempDir tmp;
  const std::string dir = makeSequence(tmp, "k", {0, 1}, false);
  writeFile(dir + "/poses.txt", cameraPoses(2));
  // Camera poses asked for, no calib.txt.
  EXPECT_NE(messageOf([&] {
              sglc::openSequence(dir, {}, 1, {"", sglc::PosesFrame::kCamera});
            }).find("calib.txt"),
            std::string::npos);
  // A calib.txt without Tr: named, with the way out.
  writeFile(dir + "/calib.txt", "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  const std::string msg = messageOf([&] { sglc::openSequence(dir); });
  EXPECT_NE(msg.find("no 'Tr:' line"), std::string::npos) << msg;
  EXPECT_NE(msg.find("--poses-frame lidar"), std::string::npos) << msg;
  EXPECT_NO_THROW(sglc::openSequence(dir, {}, 1, {"", sglc::PosesFrame::kLidar}));
  // A Tr that is no rotation.
  writeFile(dir + "/calib.txt", "Tr: 2 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_NE(messageOf([&] { sglc::openSequence(dir); }).find("not a rotation"), std::string::npos);
  EXPECT_THROW(sglc::parsePosesFrame("velodyne"), sglc::InputError);
  EXPECT_EQ(sglc::parsePosesFrame("camera"), sglc::PosesFrame::kCamera);
}

TEST(Sequence, PosesFileOption) {
  TempDir tmp;
  const std::string dir = makeSequence(tmp, "p", {0, 1, 2}, false);
  writeFile(dir + "/poses.txt", poseLine(0) + poseLine(1) + poseLine(2));
  // A TUM file elsewhere, with its stamps; TUM poses are LiDAR poses even next to a calib.txt.
  writeFile(dir + "/calib.txt", kKittiTr);
  writeFile(tmp.file("odom.tum"), "10 0 0 0 0 0 0 1\n10.1 5 0 0 0 0 0 1\n10.2 10 0 0 0 0 0 1\n");
  const sglc::Sequence s = sglc::openSequence(dir, {}, 1, {tmp.file("odom.tum"), sglc::PosesFrame::kAuto});
  EXPECT_EQ(s.poses_path, tmp.file("odom.tum"));
  EXPECT_FALSE(s.poses_from_camera);
  EXPECT_NEAR((*s.frames[2].pose)(0, 3), 10.0, 1e-12);
  EXPECT_DOUBLE_EQ(*s.frames[1].stamp, 10.1);
  EXPECT_TRUE(s.warnings.empty());
  // A missing file is named.
  const std::string msg = messageOf([&] { sglc::openSequence(dir, {}, 1, {tmp.file("nope.txt"), {}}); });
  EXPECT_NE(msg.find("nope.txt"), std::string::npos) << msg;
  // A file with the wrong number of lines: the same rule as poses.txt.
  writeFile(tmp.file("short.txt"), poseLine(0));
  EXPECT_THROW(sglc::openSequence(dir, {}, 1, {tmp.file("short.txt"), sglc::PosesFrame::kLidar}), sglc::InputError);
}

TEST(Sequence, PointTimesAreFoundBesideTheScans) {
  TempDir tmp;
  const std::string dir = makeSequence(tmp, "timed", {0, 1}, false);
  // Without point_times/ the frames have none, and the directory opens as before.
  sglc::Sequence s = sglc::openSequence(dir);
  EXPECT_TRUE(s.frames[0].point_times_path.empty());
  std::filesystem::create_directories(dir + "/point_times");
  writeFile(dir + "/point_times/000001.bin", "");
  s = sglc::openSequence(dir);
  EXPECT_TRUE(s.frames[0].point_times_path.empty());
  EXPECT_EQ(s.frames[1].point_times_path, dir + "/point_times/000001.bin");
  // Their contents: float32 per point, within 1 s of the stamp.
  sglc::writePointTimes(tmp.file("t.bin"), {0.0f, 0.05f, 0.099f});
  EXPECT_EQ(sglc::readPointTimes(tmp.file("t.bin"), 3), (std::vector<float>{0.0f, 0.05f, 0.099f}));
  EXPECT_NE(messageOf([&] { sglc::readPointTimes(tmp.file("t.bin"), 4); }).find("its scan has 4 points"),
            std::string::npos);
  sglc::writePointTimes(tmp.file("bad.bin"), {0.0f, 3.0f});
  EXPECT_NE(messageOf([&] { sglc::readPointTimes(tmp.file("bad.bin"), 2); }).find("not within 1 s"), std::string::npos);
}
