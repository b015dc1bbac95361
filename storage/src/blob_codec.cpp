#include "blob_codec.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "sglc/storage/map_store.hpp"

namespace sglc::storage::blob {
namespace {

// The first `rows` rows of M, row-major, as native doubles.
template <typename M>
std::vector<std::uint8_t> rowsBlob(const M& m, int rows) {
  std::vector<std::uint8_t> out(static_cast<std::size_t>(rows * m.cols()) * sizeof(double));
  for (int k = 0; k < rows * m.cols(); ++k) {
    const double v = m(k / m.cols(), k % m.cols());
    std::memcpy(&out[static_cast<std::size_t>(k) * sizeof(double)], &v, sizeof(double));
  }
  return out;
}

// The inverse of rowsBlob: fills the first `rows` rows of `m` (the rest keep their values); false when the
// blob has the wrong size.
template <typename M>
bool fromRowsBlob(std::span<const std::uint8_t> blob, int rows, M& m) {
  if (blob.size() != static_cast<std::size_t>(rows * m.cols()) * sizeof(double)) return false;
  for (int k = 0; k < rows * m.cols(); ++k) {
    double v;
    std::memcpy(&v, &blob[static_cast<std::size_t>(k) * sizeof(double)], sizeof(double));
    if (!std::isfinite(v)) return false;  // only finite values are ever written: this is damage
    m(k / m.cols(), k % m.cols()) = v;
  }
  return true;
}

constexpr std::size_t kRawPointBytes = 16;
// The label of every point of a cloud that came without labels (the engine labelled it itself).
constexpr std::uint32_t kNoLabel = 0xFFFFFFFFu;

}  // namespace

std::vector<std::uint8_t> fromPose(const Mat4d& T) { return rowsBlob(T, 3); }

std::optional<Mat4d> toPose(std::span<const std::uint8_t> blob) {
  Mat4d T = Mat4d::Identity();
  return fromRowsBlob(blob, 3, T) ? std::optional<Mat4d>(T) : std::nullopt;
}

Mat4d requirePose(std::span<const std::uint8_t> blob, const std::string& what, const char* field) {
  const auto T = toPose(blob);
  if (!T) throw StorageError(StorageError::Code::kCorrupt, what + " has a damaged " + field);
  return *T;
}

std::vector<std::uint8_t> fromInformation(const Mat6d& information) { return rowsBlob(information, 6); }

std::optional<Mat6d> toInformation(std::span<const std::uint8_t> blob) {
  Mat6d I;
  return fromRowsBlob(blob, 6, I) ? std::optional<Mat6d>(I) : std::nullopt;
}

std::vector<std::uint8_t> fromRawScan(const LabelledScan& scan) {
  std::vector<std::uint8_t> out(scan.points.size() * kRawPointBytes);
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    std::memcpy(&out[i * kRawPointBytes], scan.points[i].data(), 12);
    const std::uint32_t label = scan.labels.empty() ? kNoLabel : scan.labels[i];
    std::memcpy(&out[i * kRawPointBytes + 12], &label, 4);
  }
  return out;
}

std::optional<LabelledScan> toRawScan(std::span<const std::uint8_t> blob) {
  if (blob.size() % kRawPointBytes != 0) return std::nullopt;
  LabelledScan scan;
  scan.points.resize(blob.size() / kRawPointBytes);
  scan.labels.resize(blob.size() / kRawPointBytes);
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    std::memcpy(scan.points[i].data(), &blob[i * kRawPointBytes], 12);
    std::memcpy(&scan.labels[i], &blob[i * kRawPointBytes + 12], 4);
  }
  if (std::all_of(scan.labels.begin(), scan.labels.end(), [](std::uint32_t l) { return l == kNoLabel; }))
    scan.labels.clear();  // stored without labels
  return scan;
}

}  // namespace sglc::storage::blob
