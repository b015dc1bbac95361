#include "validate.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>

#include "catalogue.hpp"

namespace sglc::storage::validate {

using Code = StorageError::Code;

void scan(const NewScan& scan) {
  if (!scan.fingerprint) throw StorageError(Code::kInvalidArgument, "scan has no fingerprint");
  checkName("robot", scan.robot);
  checkName("session", scan.session);
  if (scan.stamp && !std::isfinite(*scan.stamp)) throw StorageError(Code::kInvalidArgument, "stamp is not finite");
  if (scan.odometry_pose && !scan.odometry_pose->allFinite())
    throw StorageError(Code::kInvalidArgument, "odometry pose is not finite");
  for (float v : scan.fingerprint->descriptor)
    if (!std::isfinite(v)) throw StorageError(Code::kInvalidArgument, "descriptor is not finite");
}

void loop(const LoopRecord& loop) {
  if (!loop.T.allFinite() || !std::isfinite(loop.score) || !std::isfinite(loop.fitness) || !std::isfinite(loop.rmse) ||
      (loop.information && !loop.information->allFinite()))
    throw StorageError(Code::kInvalidArgument, "loop has a non-finite value");
  if (loop.query_scan == loop.candidate_scan) throw StorageError(Code::kInvalidArgument, "a loop needs two scans");
  // NaN fails both comparisons, so it is refused here too.
  if (loop.probability && !(*loop.probability >= 0.0 && *loop.probability <= 1.0))
    throw StorageError(Code::kInvalidArgument, "loop probability must be in [0, 1]");
}

void optimised(const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames) {
  for (const auto& p : poses)
    if (!p.pose.allFinite()) throw StorageError(Code::kInvalidArgument, "optimised pose is not finite");
  for (const auto& f : frames)
    if (!f.T_map_session.allFinite()) throw StorageError(Code::kInvalidArgument, "session frame is not finite");
}

void newMap(const std::string& name, int dim) {
  checkName("map", name);
  if (dim <= 0 || dim > kMaxDescriptorDim)
    throw StorageError(Code::kInvalidArgument, "descriptor dimension must be 1.." + std::to_string(kMaxDescriptorDim));
}

void claimBackupFile(const std::string& dest) {
  const int fd = ::open(dest.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int e = errno;
    if (e == EEXIST) throw StorageError(Code::kAlreadyExists, "the backup target already exists", dest);
    throw StorageError(e == EACCES || e == EROFS || e == EPERM ? Code::kReadOnly
                       : e == ENOSPC || e == EDQUOT            ? Code::kFull
                                                               : Code::kIo,
                       "the backup file cannot be created", dest + ": " + std::strerror(e));
  }
  ::close(fd);
}

}  // namespace sglc::storage::validate
