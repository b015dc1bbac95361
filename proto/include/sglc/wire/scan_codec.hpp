// Scans on the wire (sglc.v1.Scan, IngestChunk): the one place that turns points and labels into bytes and back.
//
// Layout (proto/sglc/v1/sglc.proto): Scan.points is float32 little-endian x, y, z per point (12 bytes),
// Scan.labels one uint32 little-endian per point (4 bytes) or nothing at all (an unlabelled scan, which the
// server's labeller labels). These functions produce and accept exactly that on any host byte order.
// Every failure throws WireError with a message that says what is wrong.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "sglc/types.hpp"
#include "sglc/v1/sglc.pb.h"
#include "sglc/wire/error.hpp"

namespace sglc::wire {

inline constexpr std::size_t kPointBytes = 12;  // float32 x, y, z
inline constexpr std::size_t kLabelBytes = 4;   // uint32

// Packed bytes of the points alone / the labels alone, and back. Unpacking throws when the byte length is not a
// multiple of 12 (points) or 4 (labels); it does not look at the values.
std::string packPoints(const Points& points);
std::string packLabels(const std::vector<std::uint32_t>& labels);
Points unpackPoints(std::string_view bytes);
std::vector<std::uint32_t> unpackLabels(std::string_view bytes);

// A whole scan. packScan throws when there are labels but not one per point (coordinates are not checked: use
// decodeScan's rules, or sglc::validateScan, to catch non-finite ones before sending).
void packScan(const LabelledScan& scan, v1::Scan* out);
v1::Scan packScan(const LabelledScan& scan);
// The layout checks only: byte lengths, and labels either absent or one per point.
LabelledScan unpackScan(const v1::Scan& scan);

// What a server accepts: the layout checks, at least one point, at most `max_points` (RESOURCE_EXHAUSTED beyond,
// every other failure INVALID_ARGUMENT), and finite coordinates (the message names the first bad point).
LabelledScan decodeScan(std::string_view points, std::string_view labels,
                        std::size_t max_points = std::numeric_limits<std::size_t>::max());

// Size in bytes of a scan once packed (points + labels, + point times on the wire).
inline std::size_t packedSize(const LabelledScan& scan) {
  return scan.points.size() * kPointBytes + scan.labels.size() * kLabelBytes;
}
inline std::size_t packedSize(const v1::Scan& scan) {
  return scan.points().size() + scan.labels().size() + scan.point_times().size();
}

// Splits an ingest request into IngestChunked messages whose points + labels payload is at most
// `max_chunk_bytes` each (at least one point per chunk, whatever the limit). The first chunk carries the request
// as header with an empty scan (its twist kept) and no payload of its own; the following chunks carry the scan's
// points, labels and point times in order, cut on point boundaries so that every chunk holds whole points with
// their labels and times. The concatenation of
// the chunks' bytes is the original scan. Throws on a scan that fails unpackScan's layout checks.
std::vector<v1::IngestChunk> splitIntoChunks(const v1::IngestRequest& request, std::size_t max_chunk_bytes);

}  // namespace sglc::wire
