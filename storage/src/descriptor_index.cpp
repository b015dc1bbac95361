#include "descriptor_index.hpp"

#include <faiss/IndexFlat.h>
#include <faiss/IndexIVFFlat.h>
#include <faiss/impl/IDSelector.h>
#include <faiss/impl/io.h>
#include <faiss/index_io.h>

#include <fcntl.h>
#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

// Fortran BLAS (OpenBLAS when installed, see scripts/install-deps.sh): y = alpha * op(A) * x + beta * y.
extern "C" void sgemv_(const char* trans, const int* m, const int* n, const float* alpha, const float* a,
                       const int* lda, const float* x, const int* incx, const float* beta, float* y, const int* incy);

namespace sglc::storage {
namespace {

float squaredL2(const float* a, const float* b, int dim) {
  float s = 0;
  for (int j = 0; j < dim; ++j) {
    const float d = a[j] - b[j];
    s += d * d;
  }
  return s;
}

constexpr std::uint32_t kSnapshotMagic = 0x58494753;  // "SGIX"
constexpr std::uint32_t kSnapshotVersion = 3;  // 2: soft-binned edges (fingerprint format 2); 3: structure spectrum (3)

class FilterSelector : public faiss::IDSelector {
 public:
  FilterSelector(const std::vector<IndexEntry>& entries, const SearchFilter& filter)
      : entries_(entries), filter_(filter) {}
  bool is_member(faiss::Index::idx_t id) const override {
    return id >= 0 && static_cast<std::size_t>(id) < entries_.size() && filter_.accepts(entries_[id]);
  }

 private:
  const std::vector<IndexEntry>& entries_;
  const SearchFilter& filter_;
};

}  // namespace

bool SearchFilter::any() const {
  return !robots.empty() || !exclude_robots.empty() || !sessions.empty() || !exclude_scans.empty() ||
         (self_robot >= 0 && (exclude_recent > 0 || (!std::isnan(self_stamp) && exclude_seconds > 0)));
}

namespace {
// |a - b| without overflow: sequence numbers come from clients and may span the whole int64 range.
std::uint64_t seqDistance(std::int64_t a, std::int64_t b) {
  return a >= b ? std::uint64_t(a) - std::uint64_t(b) : std::uint64_t(b) - std::uint64_t(a);
}
}  // namespace

bool SearchFilter::accepts(const IndexEntry& e) const {
  if (e.deleted) return false;
  if (!robots.empty() && !robots.count(e.robot_id)) return false;
  if (exclude_robots.count(e.robot_id)) return false;
  if (!sessions.empty() && !sessions.count(e.session_id)) return false;
  if (exclude_scans.count(e.scan_id)) return false;
  if (e.robot_id == self_robot) {
    if (e.session_id == self_session && exclude_recent > 0 &&
        seqDistance(e.seq, self_seq) < std::uint64_t(exclude_recent))
      return false;
    if (exclude_seconds > 0 && !std::isnan(self_stamp) && !std::isnan(e.stamp) &&
        std::abs(e.stamp - self_stamp) < exclude_seconds)
      return false;
  }
  return true;
}

DescriptorIndex::DescriptorIndex(int dim, const IndexOptions& options) : dim_(dim), options_(options) {
  index_ = std::make_unique<faiss::IndexFlatL2>(dim_);
}

DescriptorIndex::~DescriptorIndex() = default;

void DescriptorIndex::build(std::vector<IndexEntry> entries, const std::vector<float>& vectors) {
  entries_ = std::move(entries);
  live_ = static_cast<std::int64_t>(entries_.size());
  const auto n = static_cast<faiss::Index::idx_t>(entries_.size());
  ivf_ = options_.type == IndexOptions::Type::kIvf && n >= std::max(options_.ivf_min_scans, 1000);
  if (!ivf_) {
    quantizer_.reset();
    index_ = std::make_unique<faiss::IndexFlatL2>(dim_);
    if (n) index_->add(n, vectors.data());
    computeNorms();
    return;
  }
  const int nlist = options_.ivf_nlist > 0 ? options_.ivf_nlist
                                           : std::clamp(static_cast<int>(std::sqrt(static_cast<double>(n))), 16, 65536);
  // k-means wants about 39 training points per cell.
  const int cells = std::max(1, std::min<int>(nlist, static_cast<int>(n / 39)));
  quantizer_ = std::make_unique<faiss::IndexFlatL2>(dim_);
  auto ivf = std::make_unique<faiss::IndexIVFFlat>(quantizer_.get(), dim_, static_cast<std::size_t>(cells));
  // Train on an evenly spaced sample (deterministic), at most 64 points per cell.
  const faiss::Index::idx_t sample = std::min<faiss::Index::idx_t>(n, static_cast<faiss::Index::idx_t>(cells) * 64);
  std::vector<float> train(static_cast<std::size_t>(sample) * dim_);
  for (faiss::Index::idx_t i = 0; i < sample; ++i) {
    const auto src = i * n / sample;
    std::memcpy(&train[static_cast<std::size_t>(i) * dim_], &vectors[static_cast<std::size_t>(src) * dim_],
                sizeof(float) * dim_);
  }
  ivf->cp.seed = 1234;
  ivf->cp.max_points_per_centroid = 64;
  ivf->train(sample, train.data());
  std::vector<faiss::Index::idx_t> ids(static_cast<std::size_t>(n));
  for (faiss::Index::idx_t i = 0; i < n; ++i) ids[static_cast<std::size_t>(i)] = i;
  ivf->add_with_ids(n, vectors.data(), ids.data());
  index_ = std::move(ivf);
  norms_.clear();
}

void DescriptorIndex::computeNorms() {
  norms_.clear();
  if (ivf_) return;
  const float* xb = static_cast<const faiss::IndexFlatL2&>(*index_).get_xb();
  norms_.resize(entries_.size());
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    const float* v = xb + i * static_cast<std::size_t>(dim_);
    float s = 0;
    for (int j = 0; j < dim_; ++j) s += v[j] * v[j];
    norms_[i] = s;
  }
}

void DescriptorIndex::add(const IndexEntry& entry, const float* vector) {
  const auto pos = static_cast<faiss::Index::idx_t>(entries_.size());
  if (ivf_) {
    index_->add_with_ids(1, vector, &pos);
  } else {
    index_->add(1, vector);
    float s = 0;
    for (int j = 0; j < dim_; ++j) s += vector[j] * vector[j];
    norms_.push_back(s);
  }
  entries_.push_back(entry);
  ++live_;
}

std::int64_t DescriptorIndex::remove(const std::unordered_set<std::int64_t>& scan_ids) {
  std::int64_t removed = 0;
  for (auto& e : entries_)
    if (!e.deleted && scan_ids.count(e.scan_id)) {
      e.deleted = true;
      ++removed;
    }
  live_ -= removed;
  return removed;
}

std::vector<SearchHit> DescriptorIndex::search(const float* query, int k, const SearchFilter& filter) const {
  std::vector<SearchHit> hits;
  if (k <= 0 || live_ == 0) return hits;
  if (!ivf_) return searchExact(query, k, filter);
  const auto kk =
      static_cast<faiss::Index::idx_t>(std::min<std::int64_t>(k, static_cast<std::int64_t>(entries_.size())));
  std::vector<float> dist(static_cast<std::size_t>(kk));
  std::vector<faiss::Index::idx_t> labels(static_cast<std::size_t>(kk), -1);
  FilterSelector selector(entries_, filter);
  faiss::SearchParametersIVF params;
  params.nprobe = static_cast<std::size_t>(options_.ivf_nprobe);
  if (filter.any() || hasTombstones()) params.sel = &selector;
  index_->search(1, query, kk, dist.data(), labels.data(), &params);
  for (faiss::Index::idx_t i = 0; i < kk; ++i) {
    const auto l = labels[static_cast<std::size_t>(i)];
    if (l < 0) continue;
    hits.push_back(
        {entries_[static_cast<std::size_t>(l)].scan_id, std::sqrt(std::max(0.0f, dist[static_cast<std::size_t>(i)]))});
  }
  std::stable_sort(hits.begin(), hits.end(), [](const SearchHit& a, const SearchHit& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.scan_id < b.scan_id;
  });
  return hits;
}

// Exact search over the flat index's vectors. Debian's FAISS is built for plain SSE2 and scans one query with
// scalar-width loops; one BLAS matrix-vector product (|x|^2 - 2 x.q) over the same storage is several times
// faster. Candidates are then re-scored with the direct squared difference, so the reported distances and the
// order do not depend on the BLAS; a margin of extra candidates absorbs the product's rounding.
std::vector<SearchHit> DescriptorIndex::searchExact(const float* query, int k, const SearchFilter& filter) const {
  const auto n = static_cast<int>(entries_.size());
  const float* xb = static_cast<const faiss::IndexFlatL2&>(*index_).get_xb();
  std::vector<float> score(norms_);  // becomes |x|^2 - 2 x.q
  const char trans = 'T';
  const int one = 1;
  const float alpha = -2.0f, beta = 1.0f;
  sgemv_(&trans, &dim_, &n, &alpha, xb, &dim_, query, &one, &beta, score.data(), &one);

  const bool filtered = filter.any() || hasTombstones();
  const std::size_t keep = static_cast<std::size_t>(k) + 16;
  // Max-heap of (score, position) holding the best `keep` accepted entries; the filter runs only on entries
  // that would enter the heap.
  std::vector<std::pair<float, int>> heap;
  heap.reserve(keep + 1);
  for (int i = 0; i < n; ++i) {
    const float s = score[static_cast<std::size_t>(i)];
    if (heap.size() == keep && !(s < heap.front().first)) continue;
    if (filtered && !filter.accepts(entries_[static_cast<std::size_t>(i)])) continue;
    heap.emplace_back(s, i);
    std::push_heap(heap.begin(), heap.end());
    if (heap.size() > keep) {
      std::pop_heap(heap.begin(), heap.end());
      heap.pop_back();
    }
  }
  std::vector<SearchHit> hits;
  hits.reserve(heap.size());
  for (const auto& [s, i] : heap)
    hits.push_back({entries_[static_cast<std::size_t>(i)].scan_id,
                    std::sqrt(squaredL2(xb + static_cast<std::size_t>(i) * dim_, query, dim_))});
  std::sort(hits.begin(), hits.end(), [](const SearchHit& a, const SearchHit& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.scan_id < b.scan_id;
  });
  if (hits.size() > static_cast<std::size_t>(k)) hits.resize(static_cast<std::size_t>(k));
  return hits;
}

void DescriptorIndex::save(const std::string& path, std::int64_t generation) const {
  faiss::VectorIOWriter writer;
  faiss::write_index(index_.get(), &writer);
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw StorageError(StorageError::Code::kIo, tmp + ": cannot write index snapshot");
    auto put = [&](const auto& v) { out.write(reinterpret_cast<const char*>(&v), sizeof(v)); };
    put(kSnapshotMagic);
    put(kSnapshotVersion);
    put(generation);
    put(static_cast<std::int32_t>(dim_));
    put(static_cast<std::uint8_t>(ivf_));
    put(static_cast<std::uint64_t>(entries_.size()));
    for (const auto& e : entries_) {
      put(e.scan_id);
      put(e.robot_id);
      put(e.session_id);
      put(e.seq);
      put(e.stamp);
    }
    put(static_cast<std::uint64_t>(writer.data.size()));
    out.write(reinterpret_cast<const char*>(writer.data.data()), static_cast<std::streamsize>(writer.data.size()));
    if (!out.flush()) throw StorageError(StorageError::Code::kIo, tmp + ": write failed");
  }
  const int fd = ::open(tmp.c_str(), O_RDONLY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
  std::filesystem::rename(tmp, path);
}

bool DescriptorIndex::load(const std::string& path, std::int64_t generation) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  auto get = [&](auto& v) { return static_cast<bool>(in.read(reinterpret_cast<char*>(&v), sizeof(v))); };
  std::uint32_t magic = 0, version = 0;
  std::int64_t gen = -1;
  std::int32_t dim = 0;
  std::uint8_t ivf = 0;
  std::uint64_t n = 0;
  if (!get(magic) || !get(version) || !get(gen) || !get(dim) || !get(ivf) || !get(n)) return false;
  if (magic != kSnapshotMagic || version != kSnapshotVersion || gen != generation || dim != dim_) return false;
  if (static_cast<bool>(ivf) != (options_.type == IndexOptions::Type::kIvf)) {
    // Configured index type changed: only an exact snapshot of a small IVF map is still right.
    if (ivf) return false;
    if (options_.type == IndexOptions::Type::kIvf && n >= static_cast<std::uint64_t>(options_.ivf_min_scans))
      return false;
  }
  if (n > (1ull << 34)) return false;
  std::vector<IndexEntry> entries(n);
  for (auto& e : entries)
    if (!get(e.scan_id) || !get(e.robot_id) || !get(e.session_id) || !get(e.seq) || !get(e.stamp)) return false;
  std::uint64_t bytes = 0;
  if (!get(bytes) || bytes > (1ull << 40)) return false;
  faiss::VectorIOReader reader;
  reader.data.resize(bytes);
  if (!in.read(reinterpret_cast<char*>(reader.data.data()), static_cast<std::streamsize>(bytes))) return false;
  try {
    std::unique_ptr<faiss::Index> index(faiss::read_index(&reader));
    if (!index || index->d != dim_ || index->ntotal != static_cast<faiss::Index::idx_t>(n)) return false;
    if (ivf) {
      auto* as_ivf = dynamic_cast<faiss::IndexIVFFlat*>(index.get());
      if (!as_ivf) return false;
      as_ivf->own_fields = true;  // the quantizer read with it belongs to it
    }
    index_ = std::move(index);
    quantizer_.reset();
  } catch (const std::exception&) {
    return false;
  }
  ivf_ = ivf;
  entries_ = std::move(entries);
  live_ = static_cast<std::int64_t>(entries_.size());
  computeNorms();
  return true;
}

}  // namespace sglc::storage
