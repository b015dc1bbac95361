// Fuzzing the bag readers (sglc/bag.hpp, sglc/ros_messages.hpp, sglc/bag_drive.hpp) on mutated MCAP files, ROS 1
// bags (seeds by Debian's python3-rosbag) and
// mutated PointCloud2 / Odometry / TFMessage bytes. The seeds are written by tests/interop/write_bag.mjs
// (@mcap/core, Foxglove's CDR serialiser): every failure must be an InputError; what is accepted must be sane
// (finite points, as many times and intensities as points, no more points than the limit).
#include <fstream>

#include "bag_writer.hpp"
#include "fuzz_util.hpp"
#include "sglc/bag.hpp"
#include "sglc/bag_drive.hpp"
#include "sglc/ros_messages.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using test::cloud;
using test::field;
using test::json;

constexpr std::int64_t kT0 = 1700000000LL * 1000000000LL;

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

json seedMessages() {
  json xyzt = {field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("t", 12, 6)};
  json messages = json::array();
  for (int i = 0; i < 4; ++i) messages.push_back(test::odometry("/odom", kT0 + i * 50000000LL, 0.5 * i, 0, 0, "lidar"));
  messages.push_back(
      cloud("/points", kT0 + 20000000LL, xyzt, 16, {{1, 2, 3, 0}, {nullptr, 0, 0, 5}, {4, 5, 6, 90000000}}));
  messages.push_back(cloud("/points", kT0 + 120000000LL, {field("x", 0, 8), field("y", 8, 8), field("z", 16, 8)}, 24,
                           {{1, 2, 3}, {4, 5, 6}}, 1, true));
  messages.push_back(test::tf("/tf_static", kT0, test::transform(kT0, "base", "lidar", 1, 0, 1.8, 0.5)));
  return messages;
}

// Every message of every topic decoded as its type; accepted clouds checked for sanity.
void readAll(Bag& bag, fuzz::Verdict& v) {
  for (std::size_t t = 0; t < bag.topics().size(); ++t) {
    const BagTopic& topic = bag.topics()[t];
    for (const auto& m : bag.messages({t})) {
      const auto bytes = bag.read(m);
      if (bytes.size() != m.size)
        v.fail("read gave " + std::to_string(bytes.size()) + " bytes, the index says " + std::to_string(m.size));
      if (topic.type == "sensor_msgs/msg/PointCloud2") {
        const RosCloud c = decodePointCloud2(bytes, topic.encoding, 1000, bag.where(m));
        if (c.points.size() > 1000) v.fail("more points than the limit");
        if (!c.times.empty() && c.times.size() != c.points.size()) v.fail("times and points differ in number");
        for (const auto& p : c.points)
          if (!p.allFinite()) v.fail("a non-finite point was accepted");
      } else if (topic.type == "nav_msgs/msg/Odometry") {
        if (!decodeOdometry(bytes, topic.encoding, bag.where(m)).pose.allFinite()) v.fail("non-finite odometry");
      } else if (topic.type == "tf2_msgs/msg/TFMessage") {
        decodeTfMessage(bytes, topic.encoding, bag.where(m));
      }
    }
  }
}

TEST(Fuzz, BagReaders) {
  const test::TempDir dir;
  std::vector<std::string> corpus;
  for (const char* compression : {"zstd", "lz4", "", "nochunks"}) {
    const std::string path = dir.file(std::string("seed-") + (*compression ? compression : "none") + ".mcap");
    test::writeBag({{"storage", "mcap"}, {"compression", compression}, {"messages", seedMessages()}}, path);
    corpus.push_back(slurp(path));
  }
  for (const char* compression : {"lz4", "bz2"}) {  // ROS 1 bags, by Debian's python3-rosbag
    const std::string path = dir.file(std::string("seed-") + compression + ".bag");
    test::writeBag({{"storage", "ros1"}, {"compression", compression}, {"messages", seedMessages()}}, path);
    corpus.push_back(slurp(path));
  }
  const std::string file = dir.file("case.mcap");
  const fuzz::Mutator mutator({std::string("\x89MCAP0\r\n", 8), "#ROSBAG V2.0\n", "op=", "compression=", "zstd", "lz4",
                               std::string("\x06", 1), std::string("\x05", 1),
                               std::string("\xff\xff\xff\xff\xff\xff\xff\x7f", 8), std::string("\0\0\0\0", 4)});
  auto make = [&](fuzz::Rng& rng, std::uint64_t i) -> std::string {
    if (i < corpus.size()) return corpus[i];
    std::string s = corpus[fuzz::below(rng, corpus.size())];
    mutator.mutate(rng, s, corpus, 1 << 16);
    return s;
  };
  auto check = [&](const std::string& bytes, fuzz::Verdict& v) -> Outcome {
    std::ofstream(file, std::ios::binary | std::ios::trunc)
        .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    try {
      auto bag = openBag(file);
      readAll(*bag, v);
      BagDriveOptions o;
      o.points_topic = "/points";
      o.odom_topic = "/odom";
      o.max_points = 1000;
      BagDrive drive(file, o);
      for (std::size_t k = 0; k < drive.frames().size(); ++k) drive.cloud(k);
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzzBytes("BagReaders", 4000, corpus.size(), make, check);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, corpus.size()) << "the unmutated seeds must be read";
    EXPECT_GT(r.rejected, 0u);
  }
}

TEST(Fuzz, RosMessages) {
  // The seeds' message bytes, taken from an uncompressed bag.
  const test::TempDir dir;
  test::writeBag({{"storage", "mcap"}, {"compression", ""}, {"messages", seedMessages()}}, dir.file("b.mcap"));
  auto bag = openBag(dir.file("b.mcap"));
  std::vector<std::string> corpus;
  std::vector<std::string> types;
  for (std::size_t t = 0; t < bag->topics().size(); ++t)
    for (const auto& m : bag->messages({t})) {
      const auto b = bag->read(m);
      corpus.emplace_back(b.begin(), b.end());
      types.push_back(bag->topics()[t].type);
    }
  const fuzz::Mutator mutator;
  auto make = [&](fuzz::Rng& rng, std::uint64_t i) -> std::string {
    if (i < corpus.size()) return corpus[i];
    std::string s = corpus[fuzz::below(rng, corpus.size())];
    mutator.mutate(rng, s, corpus, 4096);
    return s;
  };
  auto check = [&](const std::string& s, fuzz::Verdict& v) -> Outcome {
    const std::vector<std::uint8_t> bytes(s.begin(), s.end());
    int accepted = 0;
    for (const auto encoding : {MessageEncoding::kCdr, MessageEncoding::kRos1}) {
      try {
        const RosCloud c = decodePointCloud2(bytes, encoding, 1000, "fuzz");
        if (c.points.size() > 1000 || (!c.times.empty() && c.times.size() != c.points.size()))
          v.fail("a cloud's counts disagree");
        for (const auto& p : c.points)
          if (!p.allFinite()) v.fail("a non-finite point was accepted");
        ++accepted;
      } catch (const InputError& e) {
        if (!*e.what()) v.fail("InputError with an empty message");
      }
      try {
        if (!decodeOdometry(bytes, encoding, "fuzz").pose.allFinite()) v.fail("non-finite odometry");
        ++accepted;
      } catch (const InputError& e) {
        if (!*e.what()) v.fail("InputError with an empty message");
      }
      try {
        for (const auto& t : decodeTfMessage(bytes, encoding, "fuzz"))
          if (!t.T.allFinite()) v.fail("non-finite transform");
        ++accepted;
      } catch (const InputError& e) {
        if (!*e.what()) v.fail("InputError with an empty message");
      }
    }
    return accepted ? Outcome::kAccepted : Outcome::kRejected;
  };
  const auto r = fuzz::runFuzzBytes("RosMessages", 20000, corpus.size(), make, check);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, corpus.size());
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
