// Conversions between the engine's plain types and the sglc.v1 wire messages.
//
// Wire layout (see proto/sglc/v1/sglc.proto): Scan.points is float32 little-endian x, y, z per point
// (12 bytes), Scan.labels one uint32 little-endian per point (4 bytes). Transform.m is 16 doubles,
// row-major. These helpers produce and accept exactly that on any host byte order.
//
// Every function here throws sglc::InputError (core/include/sglc/types.hpp) on malformed input, with a
// message saying what is wrong.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "sglc/types.hpp"
#include "sglc/v1/sglc.pb.h"

namespace sglc::client {

inline constexpr std::size_t kPointBytes = 12;  // float32 x, y, z
inline constexpr std::size_t kLabelBytes = 4;   // uint32

// Packed bytes of the points alone / the labels alone.
std::string packPoints(const Points& points);
std::string packLabels(const std::vector<std::uint32_t>& labels);
// Inverse of the above. Throws when the byte length is not a multiple of 12 (points) or 4 (labels).
Points unpackPoints(const std::string& bytes);
std::vector<std::uint32_t> unpackLabels(const std::string& bytes);

// A whole scan. packScan throws when the point and label counts differ (coordinates are not checked:
// the server rejects non-finite ones; use sglc::validateScan first to catch them locally).
v1::Scan packScan(const LabelledScan& scan);
void packScan(const LabelledScan& scan, v1::Scan* out);
// Throws on bad byte lengths or when the point and label counts differ.
LabelledScan unpackScan(const v1::Scan& scan);

// Size in bytes of a scan once packed (points + labels).
inline std::size_t packedSize(const LabelledScan& scan) {
  return scan.points.size() * kPointBytes + scan.labels.size() * kLabelBytes;
}
inline std::size_t packedSize(const v1::Scan& scan) { return scan.points().size() + scan.labels().size(); }

// Row-major 4x4 <-> Transform. toMatrix throws unless the transform has exactly 16 finite values.
v1::Transform toTransform(const Mat4d& T);
void toTransform(const Mat4d& T, v1::Transform* out);
Mat4d toMatrix(const v1::Transform& t);
// An absent optional transform (e.g. GetScanResponse.odometry_pose when none was stored) has no values.
inline bool isSet(const v1::Transform& t) { return t.m_size() > 0; }

// Splits an ingest request into IngestChunked messages whose points + labels payload is at most
// `max_chunk_bytes` each (at least one point per chunk, whatever the limit). The first chunk carries the
// request as header with an empty scan and no payload of its own; the following chunks carry the scan's
// points and labels in order, cut on point boundaries so that every chunk holds whole points and their
// labels. The concatenation of the chunks' bytes is the original scan.
std::vector<v1::IngestChunk> splitIntoChunks(const v1::IngestRequest& request, std::size_t max_chunk_bytes);

}  // namespace sglc::client
