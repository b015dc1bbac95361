#include "relative_pose_error.hpp"

#include <ceres/autodiff_cost_function.h>

namespace sglc::posegraph {

ceres::CostFunction* relativePoseCost(const RelativePoseError& e) {
  return new ceres::AutoDiffCostFunction<RelativePoseError, 6, 7, 7>(new RelativePoseError(e));
}

}  // namespace sglc::posegraph
