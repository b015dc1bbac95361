#include "sglc/rigid.hpp"

#include <Eigen/SVD>
#include <cmath>
#include <sstream>

namespace sglc {

namespace {
std::string fmt(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}
}  // namespace

std::optional<std::string> rigidMotionError(const Mat4d& T, double tolerance) {
  if (!T.allFinite()) return "has a non-finite value (NaN or inf)";
  const Eigen::RowVector4d last = T.row(3);
  if ((last - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) return "last row is not 0 0 0 1";
  const Mat3d R = T.block<3, 3>(0, 0);
  const double ortho = (R.transpose() * R - Mat3d::Identity()).cwiseAbs().maxCoeff();
  if (!(ortho <= tolerance))
    return "rotation block is not orthonormal (max |R'R - I| = " + fmt(ortho) + ", tolerance " + fmt(tolerance) +
           "): not a rigid motion (scaled, sheared or zero)";
  const double det = R.determinant();
  if (!(std::abs(det - 1.0) <= tolerance))
    return "rotation block has determinant " + fmt(det) + ", not +1: a reflection, not a rigid motion";
  if (!(T.block<3, 1>(0, 3).norm() < kMaxTranslationM))
    return "translation is longer than " + fmt(kMaxTranslationM) + " m";
  return std::nullopt;
}

Mat4d orthonormalised(const Mat4d& T) {
  const Eigen::JacobiSVD<Mat3d> svd(T.block<3, 3>(0, 0), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3d R = svd.matrixU() * svd.matrixV().transpose();
  if (R.determinant() < 0) {
    Mat3d U = svd.matrixU();
    U.col(2) = -U.col(2);
    R = U * svd.matrixV().transpose();
  }
  Mat4d out = Mat4d::Identity();
  out.block<3, 3>(0, 0) = R;
  out.block<3, 1>(0, 3) = T.block<3, 1>(0, 3);
  return out;
}

}  // namespace sglc
