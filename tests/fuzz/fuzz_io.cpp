// Fuzzing the KITTI / SemanticKITTI file readers of sglc/io.hpp (readKittiBin, readLabels, readScan, readPoses,
// readCalibTr) on mutated files written to a temporary directory: every failure must be an InputError; what is
// accepted must agree with the file (counts, finite values, the bytes or numbers written).
#include <fstream>
#include <sstream>

#include "fuzz_util.hpp"
#include "sglc/io.hpp"
#include "test_util.hpp"

namespace sglc {
namespace {

using fuzz::Outcome;
using fuzz::Rng;

enum Reader : std::uint8_t { kBin, kLabels, kScan, kPoses, kCalib, kReaders };
const char* const kReaderNames[] = {"readKittiBin", "readLabels", "readScan", "readPoses", "readCalibTr"};

// One case: which reader, and the file contents (for readScan, the .bin then the .label file, split at `split`).
struct IoCase {
  Reader reader = kBin;
  std::string data;
  std::size_t split = 0;
};

std::string bytesOf(const IoCase& c) {
  std::string out(1, static_cast<char>(c.reader));
  const auto split = static_cast<std::uint64_t>(c.split);
  out.append(reinterpret_cast<const char*>(&split), 8);
  return out + c.data;
}

std::string describe(const IoCase& c) {
  std::string out = std::string(kReaderNames[c.reader]) + " on ";
  if (c.reader == kPoses || c.reader == kCalib) return out + fuzz::textPreview(c.data);
  if (c.reader == kScan)
    return out + ".bin " + fuzz::hexPreview(c.data.substr(0, c.split)) + " / .label " +
           fuzz::hexPreview(c.data.substr(c.split));
  return out + fuzz::hexPreview(c.data);
}

void writeFile(const std::string& path, const std::string& data) {
  std::ofstream(path, std::ios::binary | std::ios::trunc).write(data.data(), static_cast<std::streamsize>(data.size()));
}

template <typename T>
std::string rawBytes(const std::vector<T>& v) {
  return std::string(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

std::string binBytes(const std::vector<std::array<float, 4>>& pts) { return rawBytes(pts); }

std::vector<std::string> binSeeds() {
  return {binBytes({{1.5f, -2.25f, 0.125f, 0.3f}, {10.0f, 20.0f, -1.7f, 0.0f}, {-40.0f, 3.0f, 2.0f, 1.0f}}),
          binBytes({{0.0f, 0.0f, 0.0f, 0.0f}}), std::string()};
}

std::vector<std::string> labelSeeds() {
  const std::vector<std::uint32_t> a = {40, 50, 10 | (3u << 16), 80}, b = {0};
  return {rawBytes(a), rawBytes(b), std::string()};
}

std::vector<std::string> poseSeeds() {
  return {
      "1.000000e+00 0.000000e+00 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00 "
      "0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00\n"
      "9.999976e-01 5.271528e-04 -2.066039e-03 -4.690294e-02 -5.282616e-04 9.999997e-01 -5.356290e-04 "
      "-2.839928e-02 2.065756e-03 5.367189e-04 9.999977e-01 8.586941e-01\n",
      "# comment line\n\n1 0 0 5 0 1 0 -3.5 0 0 1 0.25\r\n  \t\n0 -1 0 1e3 1 0 0 -2E-2 0 0 1 +7\n",
      "1 0 0 0 0 1 0 0 0 0 1 0"};
}

std::vector<std::string> calibSeeds() {
  return {
      "P0: 7.188560e+02 0.000000e+00 6.071928e+02 0.000000e+00 0.000000e+00 7.188560e+02 1.852157e+02 "
      "0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00\n"
      "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 "
      "-7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 "
      "9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01\n",
      "Tr: 1 0 0 0 0 1 0 0 0 0 1 0"};
}

// The lines readPoses turns into poses (getline semantics: not blank or whitespace-only, not a '#' comment).
std::size_t poseLines(const std::string& text) {
  std::size_t n = 0, start = 0;
  while (start < text.size()) {
    std::size_t nl = text.find('\n', start);
    if (nl == std::string::npos) nl = text.size();
    const std::string line = text.substr(start, nl - start);
    if (line.find_first_not_of(" \t\r") != std::string::npos && line[0] != '#') ++n;
    start = nl + 1;
  }
  return n;
}

void checkPose(const Mat4d& T, const std::string& what, fuzz::Verdict& v) {
  if (!T.allFinite()) v.fail(what + " has a non-finite value");
  if (T(3, 0) != 0 || T(3, 1) != 0 || T(3, 2) != 0 || T(3, 3) != 1) v.fail(what + ": last row is not 0 0 0 1");
}

TEST(Fuzz, KittiReaders) {
  const test::TempDir dir;
  const std::string a = dir.file("a.bin"), b = dir.file("b.label"), rewritten = dir.file("rewritten");
  const std::vector<std::string> corpora[kReaders] = {binSeeds(), labelSeeds(), {}, poseSeeds(), calibSeeds()};
  std::vector<std::string> binary_corpus = binSeeds();
  for (const auto& s : labelSeeds()) binary_corpus.push_back(s);
  std::vector<std::string> text_corpus = poseSeeds();
  for (const auto& s : calibSeeds()) text_corpus.push_back(s);
  const fuzz::Mutator binary;
  const fuzz::Mutator text({" ",
                            "\t",
                            "\n",
                            "\r\n",
                            "\r",
                            "#",
                            "Tr:",
                            "Tr: ",
                            "P0: ",
                            "nan",
                            "inf",
                            "-inf",
                            "NaN",
                            "1e308",
                            "1e309",
                            "-1e309",
                            "1.7976931348623157e308",
                            "4.9e-324",
                            "1e-400",
                            "0x1p3",
                            "-0",
                            "+",
                            "-",
                            ".",
                            "e",
                            "E+",
                            "1",
                            "0",
                            "12",
                            "1 2 3 4 5 6 7 8 9 10 11 12",
                            "\v",
                            "\f",
                            std::string("\0", 1),
                            "\xff",
                            "2147483648",
                            "99999999999999999999"},
                           /*text=*/true);
  constexpr std::size_t kMaxSize = 4096;
  // The unmutated seeds first: every seed of every reader, and readScan on the first .bin / .label pair.
  std::vector<IoCase> seeds;
  for (int r = 0; r < kReaders; ++r)
    for (const auto& s : corpora[r]) seeds.push_back({static_cast<Reader>(r), s, 0});
  seeds.push_back({kScan, binSeeds()[0] + labelSeeds()[0].substr(0, 12), binSeeds()[0].size()});

  auto make = [&](Rng& rng, std::uint64_t i) -> IoCase {
    if (i < seeds.size()) return seeds[i];
    IoCase c;
    c.reader = static_cast<Reader>(fuzz::below(rng, kReaders));
    auto one = [&](Reader r) {
      const bool is_text = r == kPoses || r == kCalib;
      const fuzz::Mutator& m = is_text ? text : binary;
      if (fuzz::chance(rng, 10)) return m.random(rng, kMaxSize);
      const auto& corpus = corpora[r];
      std::string s = corpus[fuzz::below(rng, corpus.size())];
      m.mutate(rng, s, is_text ? text_corpus : binary_corpus, kMaxSize);
      return s;
    };
    if (c.reader == kScan) {
      const std::string bin = one(kBin), labels = one(kLabels);
      c.data = bin + labels;
      c.split = bin.size();
    } else {
      c.data = one(c.reader);
    }
    return c;
  };

  auto check = [&](const IoCase& c, fuzz::Verdict& v) -> Outcome {
    const std::string first = c.reader == kScan ? c.data.substr(0, c.split) : c.data;
    writeFile(a, first);
    if (c.reader == kScan) writeFile(b, c.data.substr(c.split));
    try {
      switch (c.reader) {
        case kBin: {
          std::vector<float> intensities;
          const Points pts = readKittiBin(a, &intensities);
          if (pts.size() * 16 != first.size() || intensities.size() != pts.size())
            v.fail("point or intensity count does not match the file size");
          std::string xyz_in, xyz_out;
          for (std::size_t k = 0; k < pts.size(); ++k) {
            if (!pts[k].allFinite()) v.fail("non-finite point " + std::to_string(k) + " accepted");
            xyz_in.append(first, k * 16, 12);
            xyz_out.append(reinterpret_cast<const char*>(pts[k].data()), 12);
          }
          if (xyz_in != xyz_out) v.fail("coordinates differ from the file's bytes");
          if (rawBytes(intensities) != [&] {
                std::string s;
                for (std::size_t k = 0; k < pts.size(); ++k) s.append(first, k * 16 + 12, 4);
                return s;
              }())
            v.fail("intensities differ from the file's bytes");
          break;
        }
        case kLabels: {
          const auto labels = readLabels(a);
          if (rawBytes(labels) != first) v.fail("labels differ from the file's bytes");
          break;
        }
        case kScan: {
          const LabelledScan s = readScan(a, b);
          if (s.points.size() != s.labels.size() || s.points.size() * 16 != c.split)
            v.fail("readScan: point and label counts disagree with each other or with the files");
          for (const auto& p : s.points)
            if (!p.allFinite()) {
              v.fail("readScan accepted a non-finite point");
              break;
            }
          break;
        }
        case kPoses: {
          const auto poses = readPoses(a);
          if (poses.size() != poseLines(first))
            v.fail(std::to_string(poses.size()) + " poses from " + std::to_string(poseLines(first)) + " pose lines");
          for (std::size_t k = 0; k < poses.size(); ++k) checkPose(poses[k], "pose " + std::to_string(k), v);
          // What writePoses writes (10 significant digits) reads back to the same poses, within that precision.
          // Not for values within rounding of DBL_MAX: "%.9e" rounds 1.7976931348623157e308 up to
          // 1.797693135e+308, beyond the double range, which readPoses then rejects (a known limitation of
          // writePoses, reported separately; this test is about the readers).
          bool extreme = false;
          for (const auto& T : poses) extreme = extreme || (T.array().abs() > 1e300).any();
          if (extreme) break;
          writePoses(rewritten, poses);
          try {
            const auto again = readPoses(rewritten);
            if (again.size() != poses.size())
              v.fail("writePoses -> readPoses changes the number of poses");
            else
              for (std::size_t k = 0; k < poses.size(); ++k)
                if (!((again[k] - poses[k]).array().abs() <= 1e-8 * (1.0 + poses[k].array().abs())).all()) {
                  v.fail("writePoses -> readPoses changes pose " + std::to_string(k));
                  break;
                }
          } catch (const InputError& e) {
            v.fail(std::string("readPoses rejects what writePoses wrote for accepted poses: ") + e.what());
          }
          break;
        }
        case kCalib: {
          const Mat4d T = readCalibTr(a);
          checkPose(T, "Tr", v);
          if (first.rfind("Tr:", 0) != 0 && first.find("\nTr:") == std::string::npos)
            v.fail("readCalibTr accepted a file without a 'Tr:' line");
          break;
        }
        default:
          break;
      }
    } catch (const InputError& e) {
      if (!*e.what()) v.fail("InputError with an empty message");
      return Outcome::kRejected;
    }
    return Outcome::kAccepted;
  };
  const auto r = fuzz::runFuzz<IoCase>("KittiReaders", 20000, seeds.size(), make, check, bytesOf, describe);
  // Missing files and directories are InputErrors too.
  const std::string missing = dir.file("does_not_exist");
  EXPECT_THROW(readKittiBin(missing), InputError);
  EXPECT_THROW(readLabels(dir.path().string()), InputError);
  EXPECT_THROW(readPoses(missing), InputError);
  EXPECT_THROW(readCalibTr(missing), InputError);
  if (!fuzz::onlyIteration()) {
    EXPECT_GE(r.accepted, seeds.size()) << "the valid seeds must be read";
    EXPECT_GT(r.rejected, 0u);
  }
}

}  // namespace
}  // namespace sglc
