// The plain types' rules every layer applies (sglc_types): a scan's shape, and names.
#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "sglc/names.hpp"
#include "sglc/types.hpp"

namespace sglc {
namespace {

LabelledScan fourPoints() {
  return {{{1.5f, -2.25f, 0.125f}, {-40.0f, 12.5f, -1.75f}, {0.0f, 0.0f, 0.0f}, {79.9f, -0.001f, 3.0f}}, {1, 2, 3, 4}};
}

std::string errorOf(const LabelledScan& scan) {
  try {
    validateScan(scan);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(ValidateScan, OneLabelPerPointOrNone) {
  auto scan = fourPoints();
  EXPECT_EQ(errorOf(scan), "");
  scan.labels = {1, 2, 3};
  EXPECT_EQ(errorOf(scan), "scan has 4 points but 3 labels");
  scan.labels = {1, 2, 3, 4, 5};
  EXPECT_EQ(errorOf(scan), "scan has 4 points but 5 labels");
  scan.labels.clear();  // unlabelled: the labeller labels it
  EXPECT_EQ(errorOf(scan), "");
}

TEST(ValidateScan, AnEmptyScanIsRefusedAsTheServerRefusesIt) {
  EXPECT_EQ(errorOf(LabelledScan{}), "scan is empty");
  EXPECT_EQ(errorOf(LabelledScan{{}, {}}), "scan is empty");
}

TEST(ValidateScan, NamesTheFirstNonFinitePoint) {
  auto scan = fourPoints();
  scan.points[3].y() = std::numeric_limits<float>::quiet_NaN();
  scan.points[1].z() = -std::numeric_limits<float>::infinity();
  EXPECT_NE(errorOf(scan).find("point 1 "), std::string::npos) << errorOf(scan);
  scan.points[1].z() = 0;
  EXPECT_NE(errorOf(scan).find("point 3 "), std::string::npos) << errorOf(scan);
  scan.labels.clear();
  EXPECT_NE(errorOf(scan).find("point 3 "), std::string::npos) << "unlabelled scans are checked too";
}

TEST(Names, EmptyLongAndControlCharactersAreRefusedUtf8IsNot) {
  EXPECT_EQ(nameError("campus"), std::nullopt);
  EXPECT_EQ(nameError("Straße 7 / Süd"), std::nullopt);
  EXPECT_EQ(nameError(std::string(kMaxNameBytes, 'a')), std::nullopt);
  EXPECT_EQ(nameError(""), "is empty");
  EXPECT_EQ(nameError(std::string(kMaxNameBytes + 1, 'a')), "is longer than 256 bytes");
  for (const char c : {'\0', '\n', '\t', '\x1f', '\x7f'})
    EXPECT_EQ(nameError(std::string("a") + c + "b"), "has a control character") << int(c);
}

TEST(Names, PercentEscapesAreDecodedAndAStrayPercentStandsForItself) {
  EXPECT_EQ(percentDecoded("a%2Cb%23c%20d%2a"), "a,b#c d*");
  EXPECT_EQ(percentDecoded("100%25"), "100%");
  EXPECT_EQ(percentDecoded("50% off %zz %4"), "50% off %zz %4") << "not two hex digits: literal";
  EXPECT_EQ(percentDecoded("%00x"), std::string("\0x", 2));
  EXPECT_EQ(percentDecoded("%"), "%");
  EXPECT_EQ(percentDecoded(""), "");
}

}  // namespace
}  // namespace sglc
