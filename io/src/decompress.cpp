#include "decompress.hpp"

#include <bzlib.h>
#include <lz4frame.h>

#include <climits>

#include "sglc/types.hpp"

namespace sglc {

// Decompresses an LZ4 frame into `out`, whose size is what the chunk says it holds.
void lz4Frame(const std::uint8_t* src, std::size_t n, std::vector<std::uint8_t>& out, const std::string& what) {
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION)))
    throw InputError(what + ": cannot start lz4 decompression");
  const std::size_t out_size = out.size();
  std::size_t in_at = 0, out_at = 0;
  std::size_t hint = 1;
  while (hint != 0 && in_at < n) {
    std::size_t in_n = n - in_at, out_n = out_size - out_at;
    hint = LZ4F_decompress(ctx, out.data() + out_at, &out_n, src + in_at, &in_n, nullptr);
    if (LZ4F_isError(hint)) {
      const std::string why = LZ4F_getErrorName(hint);
      LZ4F_freeDecompressionContext(ctx);
      throw InputError(what + ": lz4 data is corrupt (" + why + ")");
    }
    in_at += in_n;
    out_at += out_n;
    if (in_n == 0 && out_n == 0) break;  // no progress: the frame wants more than is there, or more room
  }
  LZ4F_freeDecompressionContext(ctx);
  if (hint != 0 || out_at != out_size)
    throw InputError(what + ": lz4 data gives " + std::to_string(out_at) + " bytes, the chunk says " +
                     std::to_string(out_size) + (hint != 0 ? " (frame truncated)" : ""));
}

void bzip2(const std::uint8_t* src, std::size_t n, std::vector<std::uint8_t>& out, const std::string& what) {
  if (n > UINT_MAX || out.size() > UINT_MAX) throw InputError(what + ": bzip2 chunk larger than 4 GiB");
  auto size = static_cast<unsigned int>(out.size());
  const int rc = BZ2_bzBuffToBuffDecompress(reinterpret_cast<char*>(out.data()), &size,
                                            const_cast<char*>(reinterpret_cast<const char*>(src)),
                                            static_cast<unsigned int>(n), 0, 0);
  if (rc == BZ_OUTBUFF_FULL) throw InputError(what + ": bzip2 data gives more bytes than the chunk says");
  if (rc != BZ_OK) throw InputError(what + ": bzip2 data is corrupt (error " + std::to_string(rc) + ")");
  if (size != out.size())
    throw InputError(what + ": bzip2 data gives " + std::to_string(size) + " bytes, the chunk says " +
                     std::to_string(out.size()));
}

}  // namespace sglc
