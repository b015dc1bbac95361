// Packing helpers: scans <-> wire bytes, transforms <-> matrices, chunking, request builders.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <random>

#include "sglc/client/client.hpp"
#include "sglc/client/packing.hpp"

namespace sc = sglc::client;
namespace v1 = sglc::v1;

namespace {

sglc::LabelledScan randomScan(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-80.f, 80.f);
  std::uniform_int_distribution<std::uint32_t> label;
  sglc::LabelledScan scan;
  for (std::size_t i = 0; i < n; ++i) {
    scan.points.emplace_back(coord(rng), coord(rng), coord(rng));
    scan.labels.push_back(label(rng));
  }
  return scan;
}

std::vector<unsigned char> bytesOf(const std::string& s) { return {s.begin(), s.end()}; }

}  // namespace

TEST(Packing, RoundTripIsExact) {
  const auto scan = randomScan(1000, 7);
  const v1::Scan packed = sc::packScan(scan);
  EXPECT_EQ(packed.points().size(), 1000u * 12);
  EXPECT_EQ(packed.labels().size(), 1000u * 4);
  EXPECT_EQ(sc::packedSize(packed), sc::packedSize(scan));
  const auto back = sc::unpackScan(packed);
  ASSERT_EQ(back.points.size(), scan.points.size());
  ASSERT_EQ(back.labels, scan.labels);
  for (std::size_t i = 0; i < scan.points.size(); ++i)
    ASSERT_EQ(std::memcmp(back.points[i].data(), scan.points[i].data(), 12), 0) << "point " << i;
}

TEST(Packing, SpecialFloatsSurviveBitForBit) {
  // Packing does not judge coordinates (the server rejects non-finite ones); it must not alter them.
  sglc::LabelledScan scan;
  scan.points = {{-0.0f, 1e-40f, std::numeric_limits<float>::max()}};
  scan.labels = {0xFFFFFFFFu};
  const auto back = sc::unpackScan(sc::packScan(scan));
  EXPECT_EQ(std::memcmp(back.points[0].data(), scan.points[0].data(), 12), 0);
  EXPECT_EQ(back.labels[0], 0xFFFFFFFFu);
}

TEST(Packing, EmptyScanRoundTrips) {
  const v1::Scan packed = sc::packScan(sglc::LabelledScan{});
  EXPECT_TRUE(packed.points().empty());
  EXPECT_TRUE(packed.labels().empty());
  const auto back = sc::unpackScan(packed);
  EXPECT_TRUE(back.points.empty());
  EXPECT_TRUE(back.labels.empty());
}

TEST(Packing, ByteLayoutIsLittleEndianFloat32AndUint32) {
  sglc::LabelledScan scan;
  scan.points = {{1.0f, -2.0f, 0.5f}, {0.0f, 3.0f, -0.25f}};
  scan.labels = {0x00010028u, 0x00000046u};  // instance 1 / class 40 (road); class 70 (vegetation)
  const v1::Scan packed = sc::packScan(scan);
  const std::vector<unsigned char> expected_points = {
      0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0xC0, 0x00, 0x00, 0x00, 0x3F,   // 1, -2, 0.5
      0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x80, 0xBE};  // 0, 3, -0.25
  const std::vector<unsigned char> expected_labels = {0x28, 0x00, 0x01, 0x00, 0x46, 0x00, 0x00, 0x00};
  EXPECT_EQ(bytesOf(packed.points()), expected_points);
  EXPECT_EQ(bytesOf(packed.labels()), expected_labels);
  EXPECT_EQ(bytesOf(sc::packPoints(scan.points)), expected_points);
  EXPECT_EQ(bytesOf(sc::packLabels(scan.labels)), expected_labels);

  // And the other way, from hand-written bytes.
  const auto points = sc::unpackPoints(std::string(expected_points.begin(), expected_points.end()));
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points[0], Eigen::Vector3f(1.0f, -2.0f, 0.5f));
  EXPECT_EQ(points[1], Eigen::Vector3f(0.0f, 3.0f, -0.25f));
  EXPECT_EQ(sc::unpackLabels(std::string(expected_labels.begin(), expected_labels.end())), scan.labels);
}

TEST(Packing, BadSizesAreRejected) {
  EXPECT_THROW(sc::unpackPoints(std::string(13, '\0')), sglc::InputError);
  EXPECT_THROW(sc::unpackPoints(std::string(11, '\0')), sglc::InputError);
  EXPECT_THROW(sc::unpackLabels(std::string(6, '\0')), sglc::InputError);

  v1::Scan mismatched;
  mismatched.set_points(std::string(24, '\0'));  // 2 points
  mismatched.set_labels(std::string(4, '\0'));   // 1 label
  EXPECT_THROW(sc::unpackScan(mismatched), sglc::InputError);

  v1::Scan ragged;
  ragged.set_points(std::string(25, '\0'));
  ragged.set_labels(std::string(8, '\0'));
  try {
    sc::unpackScan(ragged);
    FAIL() << "25 point bytes accepted";
  } catch (const sglc::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("multiple of 12"), std::string::npos) << e.what();
  }

  sglc::LabelledScan bad;
  bad.points = {{0, 0, 0}, {1, 1, 1}};
  bad.labels = {1};
  EXPECT_THROW(sc::packScan(bad), sglc::InputError);
  EXPECT_THROW(sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), bad), sglc::InputError);
}

TEST(Transforms, RoundTripIsRowMajor) {
  sglc::Mat4d T = sglc::Mat4d::Identity();
  T.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, -0.4, 1).normalized()).toRotationMatrix();
  T(0, 3) = 2.5;
  T(1, 3) = -1.25;
  T(2, 3) = 0.125;
  const v1::Transform t = sc::toTransform(T);
  ASSERT_EQ(t.m_size(), 16);
  EXPECT_EQ(t.m(1), T(0, 1));  // row-major: second value is row 0, column 1
  EXPECT_EQ(t.m(4), T(1, 0));
  EXPECT_EQ(t.m(3), 2.5);
  EXPECT_EQ(t.m(7), -1.25);
  EXPECT_EQ(t.m(11), 0.125);
  EXPECT_EQ(t.m(12), 0.0);
  EXPECT_EQ(t.m(15), 1.0);
  EXPECT_EQ(sc::toMatrix(t), T);  // exact: doubles travel unchanged
  EXPECT_TRUE(sc::isSet(t));
  EXPECT_FALSE(sc::isSet(v1::Transform{}));
}

TEST(Transforms, MalformedAreRejected) {
  v1::Transform t;
  for (int k = 0; k < 15; ++k) t.add_m(0);
  EXPECT_THROW(sc::toMatrix(t), sglc::InputError);
  t.add_m(1);
  EXPECT_NO_THROW(sc::toMatrix(t));
  t.set_m(5, std::numeric_limits<double>::quiet_NaN());
  EXPECT_THROW(sc::toMatrix(t), sglc::InputError);
  EXPECT_THROW(sc::toMatrix(v1::Transform{}), sglc::InputError);
}

TEST(Chunking, ConcatenationRebuildsTheScanAndChunksRespectTheLimit) {
  const auto scan = randomScan(1000, 3);
  sc::IngestOptions options;
  options.stamp = 12.5;
  options.query = true;
  options.query_options.set_top_k(3);
  const v1::IngestRequest request = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 42), scan, options);
  const std::size_t limit = 100 * 16 + 5;  // 100 points per chunk, plus slack that cannot hold a whole point

  const auto chunks = sc::splitIntoChunks(request, limit);
  ASSERT_EQ(chunks.size(), 1u + 10u);
  // First: the header alone, with the request minus the scan bytes.
  ASSERT_TRUE(chunks[0].has_header());
  EXPECT_TRUE(chunks[0].points().empty());
  EXPECT_TRUE(chunks[0].labels().empty());
  EXPECT_TRUE(chunks[0].header().scan().points().empty());
  EXPECT_TRUE(chunks[0].header().scan().labels().empty());
  EXPECT_EQ(chunks[0].header().key().seq(), 42);
  EXPECT_EQ(chunks[0].header().stamp(), 12.5);
  EXPECT_TRUE(chunks[0].header().query());
  EXPECT_EQ(chunks[0].header().query_options().top_k(), 3u);

  std::string points, labels;
  for (std::size_t i = 1; i < chunks.size(); ++i) {
    EXPECT_FALSE(chunks[i].has_header()) << "chunk " << i;
    EXPECT_LE(chunks[i].points().size() + chunks[i].labels().size(), limit);
    EXPECT_EQ(chunks[i].points().size() / 12, chunks[i].labels().size() / 4) << "whole points per chunk";
    EXPECT_EQ(chunks[i].points().size() % 12, 0u);
    points += chunks[i].points();
    labels += chunks[i].labels();
  }
  EXPECT_EQ(points, request.scan().points());
  EXPECT_EQ(labels, request.scan().labels());
}

TEST(Chunking, LimitBelowOnePointStillProgressesAndSmallScansTakeOneChunk) {
  const auto scan = randomScan(5, 1);
  const auto request = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), scan);
  EXPECT_EQ(sc::splitIntoChunks(request, 1).size(), 1u + 5u);
  const auto whole = sc::splitIntoChunks(request, 1 << 20);
  ASSERT_EQ(whole.size(), 2u);
  EXPECT_EQ(whole[1].points(), request.scan().points());
}

TEST(Chunking, MalformedScanIsRejected) {
  v1::IngestRequest request;
  request.mutable_scan()->set_points(std::string(24, '\0'));
  request.mutable_scan()->set_labels(std::string(4, '\0'));
  EXPECT_THROW(sc::splitIntoChunks(request, 1000), sglc::InputError);
}

TEST(Builders, IngestRequestCarriesEveryOption) {
  const auto scan = randomScan(3, 2);
  sc::IngestOptions options;
  options.stamp = 1.5;
  sglc::Mat4d pose = sglc::Mat4d::Identity();
  pose(0, 3) = 7;
  options.odometry_pose = pose;
  options.store_raw = true;
  const auto request = sc::makeIngestRequest(sc::makeKey("map", "robot", "session", 9), scan, options);
  EXPECT_EQ(request.key().map(), "map");
  EXPECT_EQ(request.key().robot(), "robot");
  EXPECT_EQ(request.key().session(), "session");
  EXPECT_EQ(request.key().seq(), 9);
  ASSERT_TRUE(request.has_stamp());
  EXPECT_EQ(request.stamp(), 1.5);
  EXPECT_EQ(sc::toMatrix(request.odometry_pose()), pose);
  EXPECT_TRUE(request.store_raw());
  EXPECT_FALSE(request.query());
  EXPECT_EQ(request.scan().points(), sc::packPoints(scan.points));

  const auto bare = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), scan);
  EXPECT_FALSE(bare.has_stamp());
  EXPECT_FALSE(sc::isSet(bare.odometry_pose()));
}

TEST(Builders, ScopeNames) {
  EXPECT_EQ(sc::parseScope("same"), v1::SCOPE_SAME_ROBOT);
  EXPECT_EQ(sc::parseScope("other"), v1::SCOPE_OTHER_ROBOTS);
  EXPECT_EQ(sc::parseScope("all"), v1::SCOPE_WHOLE_MAP);
  EXPECT_EQ(sc::parseScope("sessions"), v1::SCOPE_SESSIONS);
  EXPECT_THROW(sc::parseScope("everything"), sglc::InputError);
  EXPECT_THROW(sc::parseScope(""), sglc::InputError);
}

TEST(Errors, RpcErrorCarriesCodeAndMessageOnOneLine) {
  const sc::RpcError e("MapAdmin.ListRobots",
                       grpc::Status(grpc::StatusCode::NOT_FOUND, "unknown map 'x'\nsecond line"));
  EXPECT_EQ(e.code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(e.codeName(), "NOT_FOUND");
  EXPECT_EQ(e.statusMessage(), "unknown map 'x'\nsecond line");
  EXPECT_EQ(e.method(), "MapAdmin.ListRobots");
  EXPECT_EQ(std::string(e.what()), "NOT_FOUND: unknown map 'x' second line (MapAdmin.ListRobots)");
  EXPECT_EQ(sc::statusCodeName(grpc::StatusCode::UNAUTHENTICATED), "UNAUTHENTICATED");
  EXPECT_EQ(sc::statusCodeName(grpc::StatusCode::RESOURCE_EXHAUSTED), "RESOURCE_EXHAUSTED");
}

// The wire codec's own rules, as the server applies them (sglc/wire).
TEST(Wire, StatusCodeNamesAreGrpcsAndUnknownCodesSayTheirNumber) {
  EXPECT_EQ(sglc::wire::statusCodeName(grpc::StatusCode::OK), "OK");
  EXPECT_EQ(sglc::wire::statusCodeName(grpc::StatusCode::INVALID_ARGUMENT), "INVALID_ARGUMENT");
  EXPECT_EQ(sglc::wire::statusCodeName(grpc::StatusCode::RESOURCE_EXHAUSTED), "RESOURCE_EXHAUSTED");
  EXPECT_EQ(sglc::wire::statusCodeName(grpc::StatusCode::DATA_LOSS), "DATA_LOSS");
  EXPECT_EQ(sglc::wire::statusCodeName(grpc::StatusCode::UNAUTHENTICATED), "UNAUTHENTICATED");
  EXPECT_EQ(sglc::wire::statusCodeName(static_cast<grpc::StatusCode>(17)), "STATUS_17");
  EXPECT_EQ(sglc::wire::statusCodeName(static_cast<grpc::StatusCode>(-1)), "STATUS_-1");
}

TEST(Wire, AnUnlabelledScanRoundTrips) {
  auto scan = randomScan(50, 9);
  scan.labels.clear();
  const auto msg = sc::packScan(scan);
  EXPECT_TRUE(msg.labels().empty());
  const auto back = sc::unpackScan(msg);
  EXPECT_EQ(back.points, scan.points);
  EXPECT_TRUE(back.labels.empty());
  EXPECT_EQ(sglc::wire::decodeScan(msg.points(), msg.labels()).points, scan.points);
}

TEST(Wire, DecodeScanSaysWhatIsWrongWithTheStatusToAnswer) {
  auto scan = randomScan(10, 4);
  auto msg = sc::packScan(scan);
  auto code = [](const std::string& points, const std::string& labels, std::size_t max) {
    try {
      sglc::wire::decodeScan(points, labels, max);
    } catch (const sglc::wire::WireError& e) {
      return std::make_pair(e.code(), std::string(e.what()));
    }
    return std::make_pair(grpc::StatusCode::OK, std::string());
  };
  EXPECT_EQ(code(msg.points(), msg.labels(), 10).first, grpc::StatusCode::OK);
  const auto [too_many, m1] = code(msg.points(), msg.labels(), 9);
  EXPECT_EQ(too_many, grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(m1.find("at most 9"), std::string::npos) << m1;
  EXPECT_EQ(code("", "", 10).first, grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(msg.points(), msg.labels().substr(4), 10).first, grpc::StatusCode::INVALID_ARGUMENT);
  scan.points[7].y() = std::numeric_limits<float>::quiet_NaN();
  msg = sc::packScan(scan);
  const auto [nan, m2] = code(msg.points(), msg.labels(), 10);
  EXPECT_EQ(nan, grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(m2.find("point 7"), std::string::npos) << m2;
}

// ---- The sweep: per-point times and the twist (Scan.point_times, Scan.twist)

namespace {

std::vector<float> sweepTimes(std::size_t n) {
  std::vector<float> t(n);
  for (std::size_t i = 0; i < n; ++i) t[i] = -0.05f + 0.1f * static_cast<float>(i) / static_cast<float>(n);
  return t;
}

// The message of decodeSweep's error, or "" when it accepts.
std::string sweepError(const std::string& times, const v1::Twist& twist, std::size_t n) {
  try {
    sglc::wire::decodeSweep(times, twist, n);
  } catch (const sglc::wire::WireError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT);
    return e.what();
  }
  return "";
}

}  // namespace

TEST(Sweep, TimesAndTwistRoundTripLittleEndian) {
  const auto scan = randomScan(50, 6);
  sc::IngestOptions options;
  options.sweep.point_times = sweepTimes(50);
  options.sweep.twist = sglc::Twist{Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(0.1, 0.2, 0.3)};
  const auto request = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), scan, options);
  const std::string& bytes = request.scan().point_times();
  ASSERT_EQ(bytes.size(), 200u);
  float first;
  std::memcpy(&first, bytes.data(), 4);  // this host is little-endian, as the wire is
  EXPECT_EQ(first, -0.05f);
  const auto sweep = sglc::wire::decodeSweep(bytes, request.scan().twist(), 50);
  EXPECT_EQ(sweep.point_times, options.sweep.point_times);
  ASSERT_TRUE(sweep.twist);
  EXPECT_EQ(sweep.twist->linear, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(sweep.twist->angular, Eigen::Vector3d(0.1, 0.2, 0.3));

  // Without any: nothing on the wire, nothing decoded.
  const auto bare = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), scan);
  EXPECT_TRUE(bare.scan().point_times().empty());
  EXPECT_FALSE(bare.scan().has_twist());
  const auto none = sglc::wire::decodeSweep("", bare.scan().twist(), 50);
  EXPECT_TRUE(none.point_times.empty());
  EXPECT_FALSE(none.twist);
}

TEST(Sweep, BadTimesAndTwistsSayWhatIsWrong) {
  const auto times = sc::packPointTimes(sweepTimes(10));
  const v1::Twist none;
  EXPECT_EQ(sweepError(times, none, 10), "");
  EXPECT_NE(sweepError(times, none, 11).find("11 points but 10 point times"), std::string::npos);
  EXPECT_NE(sweepError(times.substr(1), none, 10).find("not a multiple of 4"), std::string::npos);
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), 1.5f}) {
    auto t = sweepTimes(10);
    t[6] = bad;
    const auto e = sweepError(sc::packPointTimes(t), none, 10);
    EXPECT_NE(e.find("point_times[6]"), std::string::npos) << e;
  }
  v1::Twist twist;
  sc::packTwist(sglc::Twist{}, &twist);
  EXPECT_EQ(sweepError(times, twist, 10), "");
  EXPECT_NE(sweepError("", twist, 10).find("twist is set but scan.point_times is empty"), std::string::npos);
  auto two = twist;
  two.mutable_linear()->RemoveLast();
  EXPECT_NE(sweepError(times, two, 10).find("linear has 2 values, expected 3"), std::string::npos);
  auto nan = twist;
  nan.set_angular(1, std::numeric_limits<double>::quiet_NaN());
  EXPECT_NE(sweepError(times, nan, 10).find("angular is not finite"), std::string::npos);
  // Finite but no vehicle's: a unit mistake would send every point off to infinity.
  auto fast = twist;
  fast.set_linear(0, 1e38);
  EXPECT_NE(sweepError(times, fast, 10).find("speed"), std::string::npos) << sweepError(times, fast, 10);
  auto spin = twist;
  spin.set_angular(2, 200.0);
  EXPECT_NE(sweepError(times, spin, 10).find("turn rate"), std::string::npos) << sweepError(times, spin, 10);

  // The client refuses what the server would.
  sc::IngestOptions options;
  options.sweep.point_times = sweepTimes(9);
  EXPECT_THROW(sc::makeIngestRequest(sc::makeKey("m", "r", "s", 0), randomScan(10, 1), options), sglc::InputError);
}

TEST(Sweep, ChunksCarryEachPointsTime) {
  const auto scan = randomScan(1000, 8);
  sc::IngestOptions options;
  options.sweep.point_times = sweepTimes(1000);
  options.sweep.twist = sglc::Twist{Eigen::Vector3d(5, 0, 0), Eigen::Vector3d::Zero()};
  const auto request = sc::makeIngestRequest(sc::makeKey("m", "r", "s", 1), scan, options);
  const std::size_t limit = 100 * 20;  // 100 points with their labels and times
  const auto chunks = sc::splitIntoChunks(request, limit);
  ASSERT_EQ(chunks.size(), 1u + 10u);
  EXPECT_TRUE(chunks[0].header().scan().point_times().empty());
  EXPECT_EQ(chunks[0].header().scan().twist().linear(0), 5.0) << "the twist travels in the header";
  std::string times;
  for (std::size_t i = 1; i < chunks.size(); ++i) {
    EXPECT_EQ(chunks[i].point_times().size() / 4, chunks[i].points().size() / 12) << "chunk " << i;
    EXPECT_LE(chunks[i].points().size() + chunks[i].labels().size() + chunks[i].point_times().size(), limit);
    times += chunks[i].point_times();
  }
  EXPECT_EQ(times, request.scan().point_times());

  auto broken = request;
  broken.mutable_scan()->mutable_point_times()->resize(400);
  EXPECT_THROW(sc::splitIntoChunks(broken, limit), sglc::InputError);
}
