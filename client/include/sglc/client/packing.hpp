// The client's names for the wire codec (proto/include/sglc/wire): packing scans, transforms and chunks.
//
// Wire layout (see proto/sglc/v1/sglc.proto): Scan.points is float32 little-endian x, y, z per point
// (12 bytes), Scan.labels one uint32 little-endian per point (4 bytes) or none, Scan.point_times one float32
// little-endian per point or none. Transform.m is 16 doubles,
// row-major. These helpers produce and accept exactly that on any host byte order.
//
// Every function here throws sglc::wire::WireError, an sglc::InputError (core/include/sglc/types.hpp), on
// malformed input, with a message saying what is wrong.
#pragma once

#include "sglc/wire/geometry_codec.hpp"
#include "sglc/wire/scan_codec.hpp"
#include "sglc/wire/sweep_codec.hpp"

namespace sglc::client {

using wire::kLabelBytes;
using wire::kPointBytes;
using wire::packedSize;
using wire::packLabels;
using wire::packPoints;
using wire::packPointTimes;
using wire::packScan;
using wire::packSweep;
using wire::packTwist;
using wire::splitIntoChunks;
using wire::unpackLabels;
using wire::unpackPoints;
using wire::unpackPointTimes;
using wire::unpackScan;

using wire::isSet;
using wire::toMatrix;
using wire::toTransform;

}  // namespace sglc::client
