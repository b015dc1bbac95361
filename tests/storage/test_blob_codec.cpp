// The BLOB layouts of poses, information matrices and raw clouds: exact round trips, wrong sizes refused.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>

#include "blob_codec.hpp"

namespace sglc::storage {
namespace {

TEST(BlobCodec, PosesKeepEveryBitOfTheirThreeRowsAndImplyTheLast) {
  Mat4d T = Mat4d::Identity();
  T.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.3, Vec3d(0.2, -0.5, 0.8).normalized()).toRotationMatrix();
  T.topRightCorner<3, 1>() = Vec3d(1.0 / 3.0, -2.5e-7, 1234.5678);
  const auto blob = blob::fromPose(T);
  EXPECT_EQ(blob.size(), 12 * sizeof(double));
  const auto back = blob::toPose(blob);
  ASSERT_TRUE(back);
  EXPECT_EQ(*back, T);
  EXPECT_FALSE(blob::toPose(std::span(blob).first(blob.size() - 1)));
  EXPECT_FALSE(blob::toPose({}));
}

TEST(BlobCodec, InformationMatricesRoundTripExactly) {
  Mat6d I;
  for (int k = 0; k < 36; ++k) I(k / 6, k % 6) = 1.0 / (k + 1) - 0.01 * k;
  const auto blob = blob::fromInformation(I);
  const auto back = blob::toInformation(blob);
  ASSERT_TRUE(back);
  EXPECT_EQ(*back, I);
  EXPECT_FALSE(blob::toInformation(blob::fromPose(Mat4d::Identity())));  // 12 values, not 36
}

TEST(BlobCodec, RawCloudsKeepPointsAndLabelsAndRefuseAPartialPoint) {
  LabelledScan scan;
  scan.points = {Vec3f(1.5f, -2.25f, 0.125f), Vec3f(-1e6f, 3.0f, 7.0f)};
  scan.labels = {40u, 0xFFFFFFFFu};
  const auto blob = blob::fromRawScan(scan);
  EXPECT_EQ(blob.size(), 32u);
  const auto back = blob::toRawScan(blob);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->points, scan.points);
  EXPECT_EQ(back->labels, scan.labels);
  EXPECT_FALSE(blob::toRawScan(std::span(blob).first(20)));
  const auto empty = blob::toRawScan({});
  ASSERT_TRUE(empty);
  EXPECT_TRUE(empty->points.empty());
}

// The layout is the map file's format: fixed bytes, not only a round trip (a change on both sides would pass
// that and misread every existing map).
TEST(BlobCodec, LayoutIsRowMajorDoublesAndPointThenLabel) {
  Mat4d T = Mat4d::Identity();
  T(0, 1) = 0.25;
  T(1, 0) = -4.0;
  const auto pose = blob::fromPose(T);
  double v;
  std::memcpy(&v, &pose[1 * sizeof(double)], sizeof v);  // row 0, column 1
  EXPECT_EQ(v, 0.25);
  std::memcpy(&v, &pose[4 * sizeof(double)], sizeof v);  // row 1, column 0
  EXPECT_EQ(v, -4.0);
  LabelledScan scan;
  scan.points = {Vec3f(1.0f, 2.0f, 3.0f)};
  scan.labels = {71u};
  const auto raw = blob::fromRawScan(scan);
  float y;
  std::uint32_t label;
  std::memcpy(&y, &raw[4], 4);
  std::memcpy(&label, &raw[12], 4);
  EXPECT_EQ(y, 2.0f);
  EXPECT_EQ(label, 71u);
}

// A cloud sent without labels (the engine labels it) is stored and read back without labels.
TEST(BlobCodec, UnlabelledCloudsRoundTripWithoutLabels) {
  LabelledScan scan;
  scan.points = {Vec3f(1.0f, 2.0f, 3.0f), Vec3f(-4.0f, 5.0f, 6.0f)};
  const auto blob = blob::fromRawScan(scan);
  ASSERT_EQ(blob.size(), 32u);
  const auto back = blob::toRawScan(blob);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->points, scan.points);
  EXPECT_TRUE(back->labels.empty());
}

TEST(BlobCodec, NonFiniteValuesAreDamage) {
  Mat4d T = Mat4d::Identity();
  T(2, 3) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(blob::toPose(blob::fromPose(T)));
  Mat6d I = Mat6d::Identity();
  I(5, 5) = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(blob::toInformation(blob::fromInformation(I)));
}

}  // namespace
}  // namespace sglc::storage
