// Written sequences: SemanticKITTI layout readable by the project's readers, byte-determinism, ground truth.
#include <nlohmann/json.hpp>
#include <sstream>

#include "sglc/frame_selection.hpp"
#include "sglc/io.hpp"
#include "sim/sequence.hpp"
#include "sim_test_util.hpp"

namespace sglc::sim::test {
namespace {

namespace fs = std::filesystem;

const Simulator& smallLoop() {
  static const Simulator sim(loopTrajectory(), smallConfig(7));
  return sim;
}

SequenceOptions options(const fs::path& dir, const std::string& spec, int threads = 2) {
  SequenceOptions o;
  o.out_dir = dir.string();
  o.selection_spec = spec;
  o.frames = FrameSelection::parse(spec).frames(smallLoop().numFrames());
  o.threads = threads;
  o.pairs.seed = 7;
  return o;
}

std::vector<std::vector<std::string>> rows(const fs::path& p) {
  std::ifstream in(p);
  std::vector<std::vector<std::string>> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    std::vector<std::string> cols;
    for (std::string c; ss >> c;) cols.push_back(c);
    out.push_back(cols);
  }
  return out;
}

TEST(Sequence, ProjectReadersReadTheOutput) {
  TempDir dir;
  const int n = smallLoop().numFrames();  // the route ends where it started, driven the other way
  const std::string spec = "0:4," + std::to_string(n - 13) + ":" + std::to_string(n) + ":3";
  const auto summary = writeSequence(smallLoop(), options(dir.path(), spec));
  const auto frames = FrameSelection::parse(spec).frames(smallLoop().numFrames());
  ASSERT_EQ(summary.frames, static_cast<int>(frames.size()));
  const auto poses = readPoses((dir.path() / "poses.txt").string());
  ASSERT_EQ(poses.size(), frames.size());
  EXPECT_LT((readCalibTr((dir.path() / "calib.txt").string()) - Mat4d::Identity()).norm(), 1e-12);
  std::uint64_t points = 0;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "%06zu", k);
    std::vector<float> intensity;
    const Points pts = readKittiBin((dir.path() / "velodyne" / (std::string(name) + ".bin")).string(), &intensity);
    const LabelledScan scan = readScan((dir.path() / "velodyne" / (std::string(name) + ".bin")).string(),
                                       (dir.path() / "labels" / (std::string(name) + ".label")).string());
    const Frame f = smallLoop().render(frames[k]);
    EXPECT_EQ(scan.points, f.scan.points);
    EXPECT_EQ(scan.labels, f.scan.labels);
    EXPECT_EQ(intensity, f.intensity);
    EXPECT_LT((poses[k] - f.pose).norm(), 1e-6);
    points += pts.size();
  }
  EXPECT_EQ(summary.points, points);
  // Frame map and times.
  const auto map = rows(dir.path() / "frames.txt");
  const auto times = rows(dir.path() / "times.txt");
  ASSERT_EQ(map.size(), frames.size());
  ASSERT_EQ(times.size(), frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(std::stoi(map[k][0]), frames[k]);
    EXPECT_NEAR(std::stod(times[k][0]), frames[k] * 0.1, 1e-6);
  }
  // Ground truth: the last frames come back to the start (reverse revisit).
  const auto pairs = rows(dir.path() / "pairs_distance.txt");
  const auto loops = rows(dir.path() / "loop_distance4.txt");
  ASSERT_FALSE(loops.empty());
  EXPECT_EQ(summary.loop_rows, loops.size());
  for (const auto& r : loops) {
    ASSERT_EQ(r.size(), 14u);
    const int i = std::stoi(r[0]), j = std::stoi(r[1]);
    ASSERT_LT(i, j);
    Mat4d T = Mat4d::Identity();
    for (int e = 0; e < 12; ++e) T(e / 4, e % 4) = std::stod(r[2 + e]);
    EXPECT_LT((T - poses[j].inverse() * poses[i]).norm(), 1e-5);
  }
  int positives = 0;
  for (const auto& r : pairs) {
    ASSERT_EQ(r.size(), 3u);
    EXPECT_EQ(r[0].size(), 6u);
    positives += r[2] == "1";
  }
  EXPECT_GT(positives, 0);
  EXPECT_EQ(static_cast<std::size_t>(positives), summary.positives);
  // Metadata.
  std::ifstream info_file(dir.path() / "sim_info.json");
  const auto info = nlohmann::json::parse(info_file);
  EXPECT_EQ(info["seed"].get<std::uint64_t>(), 7u);
  EXPECT_EQ(info["frames"].get<int>(), static_cast<int>(frames.size()));
  EXPECT_EQ(info["world"]["content_hash"].get<std::uint64_t>(), smallLoop().world().contentHash());
}

TEST(Sequence, SameSeedSameBytesAndSubsetsAgree) {
  TempDir a, b, c;
  writeSequence(smallLoop(), options(a.path(), "10:14", 1));
  writeSequence(smallLoop(), options(b.path(), "10:14", 3));
  writeSequence(smallLoop(), options(c.path(), "12:13"));
  for (const char* f : {"velodyne/000000.bin", "velodyne/000003.bin", "labels/000002.label", "poses.txt", "calib.txt",
                        "pairs_distance.txt", "loop_distance4.txt", "times.txt"})
    EXPECT_EQ(readFile(a.path() / f), readFile(b.path() / f)) << f;
  // Frame 12 is the same scan whatever else is selected.
  EXPECT_EQ(readFile(a.path() / "velodyne/000002.bin"), readFile(c.path() / "velodyne/000000.bin"));
  EXPECT_EQ(readFile(a.path() / "labels/000002.label"), readFile(c.path() / "labels/000000.label"));
  // Another seed, another world.
  TempDir d;
  const Simulator other(loopTrajectory(), smallConfig(8));
  auto o = options(d.path(), "10:14");
  writeSequence(other, o);
  EXPECT_NE(readFile(a.path() / "velodyne/000000.bin"), readFile(d.path() / "velodyne/000000.bin"));
}

TEST(Sequence, OdometryFileOnlyWithNoise) {
  TempDir a, b;
  writeSequence(smallLoop(), options(a.path(), "0:200:20"));
  EXPECT_FALSE(fs::exists(a.path() / "odometry.txt"));
  auto o = options(b.path(), "0:200:20");
  o.odometry = {0.02, 0.01};
  writeSequence(smallLoop(), o);
  const auto odo = readPoses((b.path() / "odometry.txt").string());
  const auto gt = readPoses((b.path() / "poses.txt").string());
  ASSERT_EQ(odo.size(), gt.size());
  EXPECT_LT((odo[0] - gt[0]).norm(), 1e-6);
  EXPECT_GT(translationError(odo.back(), gt.back()), 0.01);
}

TEST(Sequence, NeverMixesRunsUnlessToldToOverwrite) {
  TempDir dir;
  writeSequence(smallLoop(), options(dir.path(), "0:5"));
  EXPECT_THROW(writeSequence(smallLoop(), options(dir.path(), "10:12")), InputError);
  auto o = options(dir.path(), "10:12");
  o.overwrite = true;
  writeSequence(smallLoop(), o);
  EXPECT_TRUE(fs::exists(dir.path() / "velodyne" / "000001.bin"));
  EXPECT_FALSE(fs::exists(dir.path() / "velodyne" / "000002.bin"));  // from the first run: gone
  EXPECT_FALSE(fs::exists(dir.path() / "labels" / "000004.label"));
  EXPECT_EQ(readPoses((dir.path() / "poses.txt").string()).size(), 2u);
}

TEST(Sequence, RejectsBadRequests) {
  TempDir dir;
  auto o = options(dir.path(), "0:2");
  o.frames = {3, 1};
  EXPECT_THROW(writeSequence(smallLoop(), o), InputError);
  o.frames = {smallLoop().numFrames()};
  EXPECT_THROW(writeSequence(smallLoop(), o), InputError);
  o.frames = {};
  EXPECT_THROW(writeSequence(smallLoop(), o), InputError);
  o = options(dir.path() / "velodyne" / "000000.bin" / "x", "0:1");  // a file where a directory must go
  writeSequence(smallLoop(), options(dir.path(), "0:1"));
  EXPECT_THROW(writeSequence(smallLoop(), o), InputError);
}

}  // namespace
}  // namespace sglc::sim::test
