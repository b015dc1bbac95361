#include "sglc/wire/scan_codec.hpp"

#include <algorithm>
#include <bit>
#include <cstring>

namespace sglc::wire {
namespace {

static_assert(sizeof(float) == 4 && sizeof(double) == 8, "IEEE-754 single and double precision expected");
static_assert(sizeof(Vec3f) == 3 * sizeof(float), "Eigen::Vector3f must be three packed floats");
static_assert(std::endian::native == std::endian::little || std::endian::native == std::endian::big,
              "mixed-endian hosts are not supported");

constexpr bool kLittleHost = std::endian::native == std::endian::little;

std::uint32_t byteSwap32(std::uint32_t v) {
  return ((v & 0x000000FFu) << 24) | ((v & 0x0000FF00u) << 8) | ((v & 0x00FF0000u) >> 8) | ((v & 0xFF000000u) >> 24);
}

// Copies `count` 4-byte words from src to dst, converting between host order and little-endian.
void copyWordsLittleEndian(void* dst, const void* src, std::size_t count) {
  if (count == 0) return;
  if constexpr (kLittleHost) {
    std::memcpy(dst, src, count * 4);
  } else {
    auto* d = static_cast<unsigned char*>(dst);
    const auto* s = static_cast<const unsigned char*>(src);
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t w;
      std::memcpy(&w, s + 4 * i, 4);
      w = byteSwap32(w);
      std::memcpy(d + 4 * i, &w, 4);
    }
  }
}

// Point count of a scan's bytes: whole points, and labels absent or one per point.
std::size_t checkedPointCount(std::string_view points, std::string_view labels) {
  if (points.size() % kPointBytes != 0)
    throw WireError("scan.points has " + std::to_string(points.size()) +
                    " bytes, not a multiple of 12 (float32 x, y, z per point)");
  if (labels.size() % kLabelBytes != 0)
    throw WireError("scan.labels has " + std::to_string(labels.size()) +
                    " bytes, not a multiple of 4 (uint32 per point)");
  const std::size_t n = points.size() / kPointBytes;
  if (!labels.empty() && labels.size() / kLabelBytes != n)
    throw WireError("scan has " + std::to_string(n) + " points but " + std::to_string(labels.size() / kLabelBytes) +
                    " labels");
  return n;
}

}  // namespace

std::string packPoints(const Points& points) {
  std::string out(points.size() * kPointBytes, '\0');
  copyWordsLittleEndian(out.data(), points.data(), points.size() * 3);
  return out;
}

std::string packLabels(const std::vector<std::uint32_t>& labels) {
  std::string out(labels.size() * kLabelBytes, '\0');
  copyWordsLittleEndian(out.data(), labels.data(), labels.size());
  return out;
}

Points unpackPoints(std::string_view bytes) {
  if (bytes.size() % kPointBytes != 0)
    throw WireError("points: " + std::to_string(bytes.size()) +
                    " bytes is not a multiple of 12 (float32 x, y, z per point)");
  Points points(bytes.size() / kPointBytes);
  copyWordsLittleEndian(points.data(), bytes.data(), points.size() * 3);
  return points;
}

std::vector<std::uint32_t> unpackLabels(std::string_view bytes) {
  if (bytes.size() % kLabelBytes != 0)
    throw WireError("labels: " + std::to_string(bytes.size()) + " bytes is not a multiple of 4 (uint32 per point)");
  std::vector<std::uint32_t> labels(bytes.size() / kLabelBytes);
  copyWordsLittleEndian(labels.data(), bytes.data(), labels.size());
  return labels;
}

void packScan(const LabelledScan& scan, v1::Scan* out) {
  if (!scan.labels.empty() && scan.points.size() != scan.labels.size())
    throw WireError("scan has " + std::to_string(scan.points.size()) + " points but " +
                    std::to_string(scan.labels.size()) + " labels");
  *out->mutable_points() = packPoints(scan.points);
  *out->mutable_labels() = packLabels(scan.labels);
}

v1::Scan packScan(const LabelledScan& scan) {
  v1::Scan out;
  packScan(scan, &out);
  return out;
}

LabelledScan unpackScan(const v1::Scan& scan) {
  checkedPointCount(scan.points(), scan.labels());
  return {unpackPoints(scan.points()), unpackLabels(scan.labels())};
}

LabelledScan decodeScan(std::string_view points, std::string_view labels, std::size_t max_points) {
  const std::size_t n = checkedPointCount(points, labels);
  if (n > max_points)
    throw WireError(
        "scan has " + std::to_string(n) + " points, the server accepts at most " + std::to_string(max_points),
        grpc::StatusCode::RESOURCE_EXHAUSTED);
  LabelledScan scan{unpackPoints(points), unpackLabels(labels)};
  try {
    validateScan(scan);  // the rule clients apply before sending: not empty, finite coordinates
  } catch (const InputError& e) {
    throw WireError(e.what());
  }
  return scan;
}

std::vector<v1::IngestChunk> splitIntoChunks(const v1::IngestRequest& request, std::size_t max_chunk_bytes) {
  const std::string& points = request.scan().points();
  const std::string& labels = request.scan().labels();
  std::size_t n = 0;
  try {
    n = checkedPointCount(points, labels);
  } catch (const WireError& e) {
    throw WireError(std::string("cannot chunk a malformed scan: ") + e.what());
  }
  const std::string& times = request.scan().point_times();
  if (!times.empty() && times.size() != n * 4)
    throw WireError("cannot chunk a malformed scan: " + std::to_string(n) + " points but " +
                    std::to_string(times.size()) + " bytes of point times");
  const std::size_t per_point = kPointBytes + kLabelBytes + (times.empty() ? 0 : 4);
  const std::size_t per_chunk = std::max<std::size_t>(1, max_chunk_bytes / per_point);

  std::vector<v1::IngestChunk> chunks;
  chunks.reserve(1 + (n + per_chunk - 1) / per_chunk);
  v1::IngestChunk& first = chunks.emplace_back();
  *first.mutable_header() = request;
  first.mutable_header()->mutable_scan()->clear_points();
  first.mutable_header()->mutable_scan()->clear_labels();
  first.mutable_header()->mutable_scan()->clear_point_times();
  for (std::size_t begin = 0; begin < n; begin += per_chunk) {
    const std::size_t count = std::min(per_chunk, n - begin);
    v1::IngestChunk& chunk = chunks.emplace_back();
    chunk.set_points(points.substr(begin * kPointBytes, count * kPointBytes));
    if (!labels.empty()) chunk.set_labels(labels.substr(begin * kLabelBytes, count * kLabelBytes));
    if (!times.empty()) chunk.set_point_times(times.substr(begin * 4, count * 4));
  }
  return chunks;
}

}  // namespace sglc::wire
