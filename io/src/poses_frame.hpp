// The frame of an odometry file: KITTI camera poses turned into LiDAR poses, and a check that a trajectory
// moves the way a LiDAR's does (sglc/sequence.hpp, "Frames of the poses").
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "sglc/types.hpp"

namespace sglc {

// T_lidar = Tr^-1 T_cam Tr for each pose (Tr: velodyne -> camera, KITTI calib.txt's "Tr:" line): the LiDAR's
// trajectory, in the world frame the camera's trajectory uses turned into LiDAR axes.
void cameraToLidarPoses(std::vector<Mat4d*>& poses, const Mat4d& Tr);

// A warning when the trajectory's first 1 m of travel (from the first pose, in its own frame) goes mostly
// along z: a camera-frame trajectory (z forward) read as LiDAR poses. nullopt when it looks right or never
// travels 1 m.
std::optional<std::string> zMotionWarning(const std::vector<const Mat4d*>& poses, const std::string& file);

}  // namespace sglc
