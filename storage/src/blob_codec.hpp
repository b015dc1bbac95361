// How poses, information matrices and raw clouds are laid out in the database's BLOB columns (native
// doubles and floats: a map file is read on the machine type that wrote it).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "sglc/types.hpp"

namespace sglc::storage::blob {

// A rigid pose as its first three rows (12 doubles, row-major; the last row is implied).
std::vector<std::uint8_t> fromPose(const Mat4d& T);
// nullopt when the blob has the wrong size or a value that is not finite (never written: damage).
std::optional<Mat4d> toPose(std::span<const std::uint8_t> blob);
// The pose of a column that must hold one: StorageError kCorrupt "<what> has a damaged <field>" otherwise.
Mat4d requirePose(std::span<const std::uint8_t> blob, const std::string& what, const char* field);

// A 6x6 information matrix (36 doubles, row-major).
std::vector<std::uint8_t> fromInformation(const Mat6d& information);
std::optional<Mat6d> toInformation(std::span<const std::uint8_t> blob);

// A raw cloud: per point x, y, z (float) and the label (uint32), 16 bytes. A cloud without labels is stored
// with 0xFFFFFFFF on every point and read back without labels.
std::vector<std::uint8_t> fromRawScan(const LabelledScan& scan);
// nullopt when the length is not a whole number of points.
std::optional<LabelledScan> toRawScan(std::span<const std::uint8_t> blob);

}  // namespace sglc::storage::blob
