// The checks of what a caller hands the store, shared by both back-ends: kInvalidArgument before any I/O.
#pragma once

#include <vector>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage::validate {

// Names, finite stamp, pose and descriptor, a fingerprint present.
void scan(const NewScan& scan);
// Finite values, two different scans.
void loop(const LoopRecord& loop);
// Finite poses and frames.
void optimised(const std::vector<OptimisedPose>& poses, const std::vector<SessionFrame>& frames);
// The map name rule and a dimension in 1..kMaxDescriptorDim.
void newMap(const std::string& name, int dim);

// Creates the empty file `dest` for a backup, failing if it exists (O_EXCL: of two backups to one name only one
// proceeds, and a failure removes only the file its own call created): kAlreadyExists, kReadOnly, kFull, kIo.
void claimBackupFile(const std::string& dest);

}  // namespace sglc::storage::validate
