// Rigid-motion checks of poses from outside (sglc/rigid.hpp).
#include <gtest/gtest.h>

#include "sglc/rigid.hpp"

namespace sglc {
namespace {

Mat4d rotation(double yaw, double pitch) {
  Mat4d T = Mat4d::Identity();
  T.block<3, 3>(0, 0) = (Eigen::AngleAxisd(yaw, Vec3d::UnitZ()) * Eigen::AngleAxisd(pitch, Vec3d::UnitY())).matrix();
  T.block<3, 1>(0, 3) = Vec3d(3, -2, 1);
  return T;
}

TEST(Rigid, AcceptsRigidMotionsAndFloatRoundedOnes) {
  EXPECT_FALSE(rigidMotionError(Mat4d::Identity()));
  const Mat4d T = rotation(0.7, -0.2);
  EXPECT_FALSE(rigidMotionError(T));
  const Mat4d rounded = T.cast<float>().cast<double>();  // what a client that keeps poses in float sends
  EXPECT_FALSE(rigidMotionError(rounded));
  const Mat4d fixed = orthonormalised(rounded);
  const Mat3d R = fixed.block<3, 3>(0, 0);
  EXPECT_LT((R.transpose() * R - Mat3d::Identity()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_LT((fixed - T).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_TRUE((fixed.block<3, 1>(0, 3) - rounded.block<3, 1>(0, 3)).isZero(0));
}

TEST(Rigid, NamesWhatIsWrong) {
  auto error = [](const Mat4d& T) { return rigidMotionError(T).value_or("(accepted)"); };
  Mat4d zero = Mat4d::Zero();
  zero(3, 3) = 1;  // the pose that crashed the pose graph
  EXPECT_NE(error(zero).find("not orthonormal"), std::string::npos) << error(zero);
  Mat4d tiny = Mat4d::Identity() * 1e-300;
  tiny(3, 3) = 1;
  EXPECT_NE(error(tiny).find("not orthonormal"), std::string::npos);
  Mat4d scaled = rotation(0.3, 0);
  scaled.block<3, 3>(0, 0) *= 2;
  EXPECT_NE(error(scaled).find("not orthonormal"), std::string::npos);
  Mat4d sheared = Mat4d::Identity();
  sheared(0, 1) = 0.01;
  EXPECT_NE(error(sheared).find("not orthonormal"), std::string::npos);
  Mat4d reflection = Mat4d::Identity();
  reflection(2, 2) = -1;
  EXPECT_NE(error(reflection).find("determinant"), std::string::npos) << error(reflection);
  Mat4d projective = Mat4d::Identity();
  projective(3, 0) = 0.1;
  EXPECT_NE(error(projective).find("last row"), std::string::npos);
  Mat4d nan = Mat4d::Identity();
  nan(1, 3) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(error(nan).find("non-finite"), std::string::npos);
  Mat4d far = Mat4d::Identity();
  far(0, 3) = 2e8;
  EXPECT_NE(error(far).find("translation"), std::string::npos);
  Mat4d slightly = Mat4d::Identity();
  slightly(0, 1) = 5e-4;  // within the tolerance
  EXPECT_FALSE(rigidMotionError(slightly));
}

}  // namespace
}  // namespace sglc
