// A small, bounded, deterministic fuzzing harness for GoogleTest: every test feeds a decoder random and mutated
// inputs for a fixed time budget and at most a fixed number of iterations, and fails when an input crashes the
// process (ASan/UBSan abort), when an exception other than the decoder's documented one escapes, or when an
// accepted input breaks a property the test checks.
//
// Reproducing a failure. The input of iteration i depends only on the seed and i (each iteration has its own
// generator, seeded from both; the corpus never changes during a run), so a failure message, or the line printed
// when the process dies, names everything needed:
//   SGLC_FUZZ_SEED=<seed> SGLC_FUZZ_ITERATION=<i> fuzz_tests --gtest_filter=<test>
// runs exactly that one input. The failing input is also written to a file (its path is printed; for tests whose
// input is not a plain byte string, the file holds the test's encoding of the case).
//
// Environment:
//   SGLC_FUZZ_SECONDS         time budget per test (default 3; the iteration cap still applies)
//   SGLC_FUZZ_MAX_ITERATIONS  overrides every test's iteration cap (for long runs: a large number)
//   SGLC_FUZZ_SEED            base seed (default kDefaultSeed, decimal or 0x hex)
//   SGLC_FUZZ_ITERATION       run only this iteration (reproduction)
//   SGLC_FUZZ_MAX_FAILURES    failing cases reported before a test stops (default 3)
#pragma once

#include <gtest/gtest.h>

#include <cxxabi.h>
#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <typeinfo>
#include <vector>

#if defined(__SANITIZE_ADDRESS__)
#include <dlfcn.h>
#include <sanitizer/common_interface_defs.h>
#endif
#include <unistd.h>
#include <csignal>

namespace sglc::fuzz {

using Rng = std::mt19937_64;
inline constexpr std::uint64_t kDefaultSeed = 0x5361C0FFEE5EED01ULL;

// ------------------------------------------------------------------------------------------------------------
// Settings from the environment.

struct Settings {
  double seconds = 3.0;
  std::uint64_t max_iterations = 0;
  std::uint64_t seed = kDefaultSeed;
  std::optional<std::uint64_t> only_iteration;
  std::uint64_t max_failures = 3;
};

inline std::optional<std::uint64_t> envU64(const char* name) {
  const char* v = std::getenv(name);
  if (!v || !*v) return std::nullopt;
  char* end = nullptr;
  const unsigned long long x = std::strtoull(v, &end, 0);
  if (end == v || *end != '\0') {
    ADD_FAILURE() << name << "=" << v << " is not an unsigned integer";
    return std::nullopt;
  }
  return static_cast<std::uint64_t>(x);
}

inline Settings settings(std::uint64_t default_cap) {
  Settings s;
  s.max_iterations = default_cap;
  if (const char* v = std::getenv("SGLC_FUZZ_SECONDS"); v && *v) {
    char* end = nullptr;
    const double d = std::strtod(v, &end);
    if (end != v && *end == '\0' && std::isfinite(d) && d >= 0)
      s.seconds = d;
    else
      ADD_FAILURE() << "SGLC_FUZZ_SECONDS=" << v << " is not a number of seconds";
  }
  if (auto n = envU64("SGLC_FUZZ_MAX_ITERATIONS")) s.max_iterations = *n;
  if (auto n = envU64("SGLC_FUZZ_SEED")) s.seed = *n;
  s.only_iteration = envU64("SGLC_FUZZ_ITERATION");
  if (auto n = envU64("SGLC_FUZZ_MAX_FAILURES")) s.max_failures = std::max<std::uint64_t>(1, *n);
  return s;
}

inline std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

// The generator of one iteration: a function of the base seed and the iteration only.
inline Rng iterationRng(std::uint64_t seed, std::uint64_t iteration) {
  return Rng(splitmix64(seed ^ splitmix64(iteration + 0x51ULL)));
}

inline std::uint64_t below(Rng& rng, std::uint64_t n) { return n == 0 ? 0 : rng() % n; }
inline bool chance(Rng& rng, unsigned percent) { return rng() % 100 < percent; }

// ------------------------------------------------------------------------------------------------------------
// Printing inputs.

inline std::string hexPreview(const std::string& bytes, std::size_t max_bytes = 96) {
  static const char* digits = "0123456789abcdef";
  std::string out = std::to_string(bytes.size()) + " bytes: ";
  for (std::size_t i = 0; i < std::min(bytes.size(), max_bytes); ++i) {
    out += digits[static_cast<unsigned char>(bytes[i]) >> 4];
    out += digits[static_cast<unsigned char>(bytes[i]) & 15];
    if (i % 4 == 3) out += ' ';
  }
  if (bytes.size() > max_bytes) out += "...";
  return out;
}

// Text with non-printable bytes escaped (C style), at most max_chars of it.
inline std::string textPreview(const std::string& text, std::size_t max_chars = 600) {
  std::string out = std::to_string(text.size()) + " chars: \"";
  char buf[8];
  for (std::size_t i = 0; i < std::min(text.size(), max_chars); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n')
      out += "\\n";
    else if (c == '\t')
      out += "\\t";
    else if (c == '\\')
      out += "\\\\";
    else if (c == '"')
      out += "\\\"";
    else if (c < 0x20 || c >= 0x7f) {
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      out += buf;
    } else
      out += static_cast<char>(c);
  }
  out += text.size() > max_chars ? "\"..." : "\"";
  return out;
}

inline std::string demangle(const char* name) {
  int status = 0;
  std::unique_ptr<char, void (*)(void*)> d(abi::__cxa_demangle(name, nullptr, nullptr, &status), std::free);
  return status == 0 && d ? std::string(d.get()) : std::string(name);
}

// Type and message of the exception being handled (call inside a catch block).
inline std::string currentExceptionDescription() {
  const std::type_info* type = abi::__cxa_current_exception_type();
  std::string out = type ? demangle(type->name()) : std::string("<unknown type>");
  try {
    throw;
  } catch (const std::exception& e) {
    out += std::string(": ") + e.what();
  } catch (...) {
  }
  return out;
}

// ------------------------------------------------------------------------------------------------------------
// The case being run, for the message printed when the process dies (sanitizer abort or a fatal signal).

struct CurrentCase {
  const char* test = nullptr;
  std::uint64_t seed = 0;
  std::uint64_t iteration = 0;
  const std::string* input = nullptr;  // bytes of the current input, written to a file on death
};
inline CurrentCase g_current;

// $TMPDIR/sglc_fuzz_<test>[_<iteration>].bin: the bytes of a failing case (the input itself for tests of byte
// strings; the test's encoding of the case otherwise).
inline std::string crashFilePath(const char* test, const std::string& suffix = "") {
  std::string name = std::string("sglc_fuzz_") + test + suffix;
  for (auto& c : name)
    if (c == '/' || c == '.' || c == ' ') c = '_';
  return (std::filesystem::temp_directory_path() / (name + ".bin")).string();
}

inline void onDeath() {
  if (!g_current.test) return;
  std::fprintf(stderr,
               "\n*** sglc fuzz: the process died in %s at iteration %" PRIu64 " (seed 0x%" PRIx64
               "); reproduce with SGLC_FUZZ_SEED=0x%" PRIx64 " SGLC_FUZZ_ITERATION=%" PRIu64
               " fuzz_tests --gtest_filter='*%s*'\n",
               g_current.test, g_current.iteration, g_current.seed, g_current.seed, g_current.iteration,
               g_current.test);
  if (g_current.input) {
    const std::string path = crashFilePath(g_current.test);
    if (std::FILE* f = std::fopen(path.c_str(), "wb")) {
      std::fwrite(g_current.input->data(), 1, g_current.input->size(), f);
      std::fclose(f);
      std::fprintf(stderr, "*** sglc fuzz: input (%zu bytes) written to %s\n", g_current.input->size(), path.c_str());
    }
  }
  std::fflush(stderr);
}

#if !defined(__SANITIZE_ADDRESS__)
// Without sanitizers: a fatal signal prints the case (async-signal-safe: write(2) of fixed buffers only).
inline void writeU64(std::uint64_t v) {
  char buf[24];
  int n = 0;
  do {
    buf[sizeof(buf) - 1 - n++] = static_cast<char>('0' + v % 10);
    v /= 10;
  } while (v && n < 20);
  (void)!::write(2, buf + sizeof(buf) - n, static_cast<std::size_t>(n));
}
inline void fatalSignal(int sig) {
  static const char a[] = "\n*** sglc fuzz: fatal signal in ";
  static const char b[] = " at iteration ";
  static const char c[] = "; seed (decimal) ";
  static const char d[] = "; reproduce with SGLC_FUZZ_SEED and SGLC_FUZZ_ITERATION\n";
  (void)!::write(2, a, sizeof(a) - 1);
  if (g_current.test) (void)!::write(2, g_current.test, std::strlen(g_current.test));
  (void)!::write(2, b, sizeof(b) - 1);
  writeU64(g_current.iteration);
  (void)!::write(2, c, sizeof(c) - 1);
  writeU64(g_current.seed);
  (void)!::write(2, d, sizeof(d) - 1);
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}
#endif

inline void installDeathReport() {
  static bool installed = false;
  if (installed) return;
  installed = true;
#if defined(__SANITIZE_ADDRESS__)
  __sanitizer_set_death_callback(&onDeath);
  // GCC links UBSan as a runtime of its own (libubsan.so) with its own death callback: register there too.
  if (void* ubsan = dlopen("libubsan.so.1", RTLD_NOW | RTLD_NOLOAD))
    if (auto set = reinterpret_cast<void (*)(void (*)())>(dlsym(ubsan, "__sanitizer_set_death_callback")))
      set(&onDeath);
#else
  for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) std::signal(sig, &fatalSignal);
#endif
}

// ------------------------------------------------------------------------------------------------------------
// Mutations.

inline const std::vector<std::uint64_t>& interestingIntegers() {
  static const std::vector<std::uint64_t> v = {0,
                                               1,
                                               2,
                                               3,
                                               4,
                                               7,
                                               8,
                                               15,
                                               16,
                                               17,
                                               31,
                                               32,
                                               63,
                                               64,
                                               100,
                                               127,
                                               128,
                                               255,
                                               256,
                                               1000,
                                               1024,
                                               4096,
                                               0x7fff,
                                               0x8000,
                                               0xffff,
                                               0x10000,
                                               (1u << 24) - 1,
                                               1u << 24,
                                               (1u << 24) + 1,
                                               1u << 26,
                                               0x7fffffff,
                                               0x80000000,
                                               0xfffffffe,
                                               0xffffffff,
                                               0x100000000ULL,
                                               0x7fffffffffffffffULL,
                                               0x8000000000000000ULL,
                                               ~0ULL - 1,
                                               ~0ULL,
                                               static_cast<std::uint64_t>(-2),
                                               static_cast<std::uint64_t>(-16),
                                               static_cast<std::uint64_t>(-128),
                                               static_cast<std::uint64_t>(-32768),
                                               static_cast<std::uint64_t>(-2147483647LL - 1)};
  return v;
}

inline const std::vector<double>& interestingReals() {
  static const std::vector<double> v = {0.0,
                                        -0.0,
                                        1.0,
                                        -1.0,
                                        0.5,
                                        1e-30,
                                        1e30,
                                        -1e30,
                                        1e38,
                                        3.4028234663852886e38,
                                        1.7976931348623157e308,
                                        -1.7976931348623157e308,
                                        2.2250738585072014e-308,
                                        4.9406564584124654e-324,
                                        1.401298464324817e-45,
                                        65536.0,
                                        2147483648.0,
                                        1e8,
                                        std::numeric_limits<double>::quiet_NaN(),
                                        -std::numeric_limits<double>::quiet_NaN(),
                                        std::numeric_limits<double>::signaling_NaN(),
                                        std::numeric_limits<double>::infinity(),
                                        -std::numeric_limits<double>::infinity()};
  return v;
}

inline double interestingReal(Rng& rng) { return interestingReals()[below(rng, interestingReals().size())]; }

class Mutator {
 public:
  // `dictionary`: tokens inserted or overwritten as a whole (syntax of text formats, magic values).
  // `text`: the input is line-oriented text; also duplicates, deletes and swaps lines.
  explicit Mutator(std::vector<std::string> dictionary = {}, bool text = false)
      : dictionary_(std::move(dictionary)), text_(text) {}

  // 1..8 stacked mutations (fewer more often); the result is at most max_size bytes.
  void mutate(Rng& rng, std::string& data, const std::vector<std::string>& corpus, std::size_t max_size) const {
    const int n = 1 + static_cast<int>(std::min<std::uint64_t>(7, std::countr_zero(rng() | (1ULL << 7))));
    for (int k = 0; k < n; ++k) once(rng, data, corpus);
    if (data.size() > max_size) data.resize(max_size);
  }

  // Random bytes, or random text made of dictionary tokens and printable characters for text formats.
  std::string random(Rng& rng, std::size_t max_size) const {
    const std::size_t len = chance(rng, 50) ? below(rng, 33) : below(rng, max_size + 1);
    std::string out;
    if (text_ && !dictionary_.empty()) {
      while (out.size() < len) {
        if (chance(rng, 60))
          out += dictionary_[below(rng, dictionary_.size())];
        else
          out += static_cast<char>(chance(rng, 90) ? 0x20 + below(rng, 95) : below(rng, 256));
      }
      out.resize(std::min(out.size(), max_size));
      return out;
    }
    out.resize(len);
    for (auto& c : out) c = static_cast<char>(rng());
    return out;
  }

 private:
  static std::size_t chunkLength(Rng& rng, std::size_t limit) {
    if (limit == 0) return 0;
    const std::size_t cap = chance(rng, 80) ? std::min<std::size_t>(limit, 32) : limit;
    return 1 + below(rng, cap);
  }

  template <typename T>
  static void put(std::string& data, std::size_t pos, T v) {
    if (pos + sizeof(T) <= data.size()) std::memcpy(data.data() + pos, &v, sizeof(T));
  }

  void once(Rng& rng, std::string& data, const std::vector<std::string>& corpus) const {
    const int ops = text_ ? 16 : 13;
    const int op = static_cast<int>(below(rng, static_cast<std::uint64_t>(ops)));
    const std::size_t size = data.size();
    switch (op) {
      case 0:  // flip 1..8 bits
        if (size) {
          const int bits = 1 + static_cast<int>(below(rng, 8));
          for (int b = 0; b < bits; ++b) data[below(rng, size)] ^= static_cast<char>(1u << below(rng, 8));
        }
        break;
      case 1:  // random byte
        if (size) data[below(rng, size)] = static_cast<char>(rng());
        break;
      case 2: {  // insert random bytes
        std::string ins(chunkLength(rng, 64), '\0');
        for (auto& c : ins) c = static_cast<char>(rng());
        data.insert(below(rng, size + 1), ins);
        break;
      }
      case 3:  // delete a chunk
        if (size) {
          const std::size_t pos = below(rng, size);
          data.erase(pos, chunkLength(rng, size - pos));
        }
        break;
      case 4:  // duplicate a chunk somewhere
        if (size) {
          const std::size_t pos = below(rng, size);
          const std::string chunk = data.substr(pos, chunkLength(rng, size - pos));
          data.insert(below(rng, size + 1), chunk);
        }
        break;
      case 5:  // truncate
        data.resize(below(rng, size + 1));
        break;
      case 6:  // splice: a prefix of this input and a suffix of another
        if (!corpus.empty()) {
          const std::string& other = corpus[below(rng, corpus.size())];
          data = data.substr(0, below(rng, size + 1)) + other.substr(below(rng, other.size() + 1));
        }
        break;
      case 7: {  // interesting integer, 1/2/4/8 bytes, at a random or aligned offset
        if (!size) break;
        const std::uint64_t v = interestingIntegers()[below(rng, interestingIntegers().size())];
        const std::size_t width = std::size_t{1} << below(rng, 4);
        std::size_t pos = below(rng, size);
        if (chance(rng, 50)) pos -= pos % width;
        if (width == 1)
          put<std::uint8_t>(data, pos, static_cast<std::uint8_t>(v));
        else if (width == 2)
          put<std::uint16_t>(data, pos, static_cast<std::uint16_t>(v));
        else if (width == 4)
          put<std::uint32_t>(data, pos, static_cast<std::uint32_t>(v));
        else
          put<std::uint64_t>(data, pos, v);
        break;
      }
      case 8: {  // interesting float or double
        if (!size) break;
        const double v = interestingReals()[below(rng, interestingReals().size())];
        std::size_t pos = below(rng, size);
        if (chance(rng, 50)) {
          if (chance(rng, 70)) pos -= pos % 4;
          put<float>(data, pos, static_cast<float>(v));
        } else {
          if (chance(rng, 70)) pos -= pos % 8;
          put<double>(data, pos, v);
        }
        break;
      }
      case 9:  // small arithmetic on a byte
        if (size) data[below(rng, size)] += static_cast<char>(static_cast<int>(below(rng, 33)) - 16);
        break;
      case 10:  // overwrite with a chunk of this or another input
        if (size) {
          const std::string& src = corpus.empty() || chance(rng, 50) ? data : corpus[below(rng, corpus.size())];
          if (src.empty()) break;
          const std::size_t from = below(rng, src.size());
          const std::string chunk = src.substr(from, chunkLength(rng, src.size() - from));
          const std::size_t to = below(rng, size);
          data.replace(to, std::min(chunk.size(), size - to), chunk.substr(0, size - to));
        }
        break;
      case 11:  // insert a dictionary token
        if (!dictionary_.empty()) data.insert(below(rng, size + 1), dictionary_[below(rng, dictionary_.size())]);
        break;
      case 12:  // overwrite with a dictionary token
        if (!dictionary_.empty() && size) {
          const std::string& tok = dictionary_[below(rng, dictionary_.size())];
          const std::size_t pos = below(rng, size);
          data.replace(pos, std::min(tok.size(), size - pos), tok);
        }
        break;
      default:  // 13..15: line operations (text only)
        lineOp(rng, data, op - 13);
        break;
    }
  }

  static void lineOp(Rng& rng, std::string& data, int which) {
    std::vector<std::string> lines;
    std::size_t start = 0;
    while (start < data.size()) {
      const std::size_t nl = data.find('\n', start);
      const std::size_t end = nl == std::string::npos ? data.size() : nl + 1;
      lines.push_back(data.substr(start, end - start));
      start = end;
    }
    if (lines.empty()) return;
    const std::size_t a = below(rng, lines.size()), b = below(rng, lines.size());
    if (which == 0)
      lines.insert(lines.begin() + static_cast<std::ptrdiff_t>(b), lines[a]);
    else if (which == 1)
      lines.erase(lines.begin() + static_cast<std::ptrdiff_t>(a));
    else
      std::swap(lines[a], lines[b]);
    data.clear();
    for (const auto& l : lines) data += l;
  }

  std::vector<std::string> dictionary_;
  bool text_;
};

// ------------------------------------------------------------------------------------------------------------
// The loop.

enum class Outcome { kAccepted, kRejected };

// Collects the property violations of one case.
class Verdict {
 public:
  void fail(const std::string& what) {
    if (!failures_.empty()) failures_ += "; ";
    failures_ += what;
  }
  bool failed() const { return !failures_.empty(); }
  const std::string& failures() const { return failures_; }

 private:
  std::string failures_;
};

struct Report {
  std::uint64_t iterations = 0;
  std::uint64_t accepted = 0;
  std::uint64_t rejected = 0;
  std::uint64_t failures = 0;
  double seconds = 0;
};

// Runs cases 0, 1, 2, ... until the time budget or the iteration cap is reached (the first `min_iterations`
// run regardless of time: the unmutated seeds), or until SGLC_FUZZ_MAX_FAILURES (3) cases failed. For each case i,
// `make(rng, i)` builds the input from iteration i's generator and `check(input, verdict)` runs the decoder on it: it
// catches the decoder's documented exception itself (Outcome::kRejected) and records property violations in the
// verdict; any exception that escapes `check` is a failure. `bytes(input)` is what gets written to a file
// when the case fails or the process dies; `describe(input)` goes into the failure message.
template <typename Input, typename Make, typename Check, typename Bytes, typename Describe>
Report runFuzz(const char* test, std::uint64_t default_cap, std::uint64_t min_iterations, Make&& make, Check&& check,
               Bytes&& bytes, Describe&& describe) {
  installDeathReport();
  const Settings s = settings(default_cap);
  ::testing::Test::RecordProperty("fuzz_seed", std::to_string(s.seed));
  ::testing::Test::RecordProperty("fuzz_budget_seconds", std::to_string(s.seconds));
  ::testing::Test::RecordProperty("fuzz_max_iterations", std::to_string(s.max_iterations));
  char seed_hex[32];
  std::snprintf(seed_hex, sizeof(seed_hex), "0x%" PRIx64, s.seed);
  SCOPED_TRACE(std::string("fuzz seed ") + seed_hex + " (SGLC_FUZZ_SEED), test " + test);
  std::printf("[ fuzz     ] %s: seed %s, budget %.1f s, at most %" PRIu64 " iterations\n", test, seed_hex, s.seconds,
              s.max_iterations);
  std::fflush(stdout);

  Report r;
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  std::string current_bytes;
  g_current = {test, s.seed, 0, &current_bytes};
  const std::uint64_t first = s.only_iteration.value_or(0);
  const std::uint64_t last = s.only_iteration ? *s.only_iteration + 1 : s.max_iterations;
  for (std::uint64_t i = first; i < last; ++i) {
    if (!s.only_iteration && i >= min_iterations && elapsed() >= s.seconds) break;
    g_current.iteration = i;
    current_bytes.clear();
    Rng rng = iterationRng(s.seed, i);
    Input input = make(rng, i);
    current_bytes = bytes(input);
    Verdict verdict;
    try {
      const Outcome o = check(input, verdict);
      ++(o == Outcome::kAccepted ? r.accepted : r.rejected);
    } catch (...) {
      verdict.fail("undocumented exception escaped: " + currentExceptionDescription());
    }
    ++r.iterations;
    if (verdict.failed()) {
      ++r.failures;
      const std::string path = crashFilePath(test, "_" + std::to_string(i));
      std::ofstream(path, std::ios::binary)
          .write(current_bytes.data(), static_cast<std::streamsize>(current_bytes.size()));
      ADD_FAILURE() << test << " iteration " << i << ": " << verdict.failures() << "\n  input: " << describe(input)
                    << "\n  input written to " << path << "\n  reproduce: SGLC_FUZZ_SEED=" << seed_hex
                    << " SGLC_FUZZ_ITERATION=" << i << " fuzz_tests --gtest_filter='*" << test << "*'";
      if (r.failures >= s.max_failures) break;
    }
  }
  g_current = {};
  r.seconds = elapsed();
  ::testing::Test::RecordProperty("fuzz_iterations", std::to_string(r.iterations));
  ::testing::Test::RecordProperty("fuzz_accepted", std::to_string(r.accepted));
  ::testing::Test::RecordProperty("fuzz_rejected", std::to_string(r.rejected));
  std::printf("[ fuzz     ] %s: %" PRIu64 " iterations in %.2f s: %" PRIu64 " accepted, %" PRIu64 " rejected, %" PRIu64
              " failed\n",
              test, r.iterations, r.seconds, r.accepted, r.rejected, r.failures);
  std::fflush(stdout);
  return r;
}

// The common case: the input is a byte string.
template <typename Make, typename Check>
Report runFuzzBytes(const char* test, std::uint64_t default_cap, std::uint64_t min_iterations, Make&& make,
                    Check&& check, bool text = false) {
  return runFuzz<std::string>(
      test, default_cap, min_iterations, std::forward<Make>(make), std::forward<Check>(check),
      [](const std::string& in) { return in; },
      [text](const std::string& in) { return text ? textPreview(in) : hexPreview(in); });
}

// True when SGLC_FUZZ_ITERATION selects a single case: tests skip their expectations about the whole run then.
inline bool onlyIteration() { return std::getenv("SGLC_FUZZ_ITERATION") && *std::getenv("SGLC_FUZZ_ITERATION"); }

}  // namespace sglc::fuzz
