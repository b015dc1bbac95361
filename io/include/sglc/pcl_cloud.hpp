// PCD (ascii, binary, binary_compressed) and PLY (ascii, binary) point clouds, read through PCL's I/O module.
//
// Any field layout is accepted: x, y, z of any numeric type, and the labels from the field named
// `label_field` ("label" in PCL's PointXYZL and PointXYZRGBL) when the file has one, of any integer type or a
// float holding whole numbers. Points whose x, y or z is not finite are refused (organised clouds with NaN
// holes: remove them first), as are negative or non-integer labels. Every failure throws InputError naming
// the file.
#pragma once

#include <string>

#include "sglc/types.hpp"

namespace sglc {

// `labels` of the result is empty when the file has no `label_field`.
LabelledScan readPclCloud(const std::string& path, const std::string& label_field = "label");

// Writes an ascii or binary PCD with fields x y z (float32) and, when `scan.labels` is not empty, label
// (uint32): PCL's PointXYZ / PointXYZL layouts. For tests and tools.
void writePcd(const std::string& path, const LabelledScan& scan, bool binary = true);

}  // namespace sglc
