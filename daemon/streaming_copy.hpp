// A copy into memory that another thread reads next, written past this thread's cache.
//
// The decode thread copies each datagram into a raw batch, which the writer reads on the other
// CPU some 100 ms later and then hands back. An ordinary store first fetches the line it writes
// (a read for ownership); the line was the writer's last, so every one of them missed: `perf`
// put the decode thread's copy into the batch at 17 % of its samples at 3600 packets/s, nearly
// all of it on the copy's first store (docs/performance.md, ninth round). Non-temporal stores
// write whole lines without that fetch.
//
// Sanitizer builds copy with memcpy: the sanitizers do not see the intrinsics' stores.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

#if defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#include <emmintrin.h>
#define PANDARCAP_STREAMING_STORES 1
#endif

namespace pandarcap {

// The granule the copy writes in: `bytes` is rounded up to it in `dst`, which must have that
// much room (and be aligned to it). `src` is read for exactly `bytes`: it may be a datagram in
// the packet ring's mapping, whose last block ends where the mapping does.
inline constexpr std::size_t kStreamingGranule = 16;

// Copies `bytes` from `src` to `dst`; the rest of `dst`'s last granule is left undefined. The
// stores are weakly ordered: call streaming_stores_done() before the memory is handed to another
// thread.
inline void streaming_copy(void* dst, const void* src, std::size_t bytes) noexcept {
#ifdef PANDARCAP_STREAMING_STORES
  auto* out = static_cast<__m128i*>(dst);
  const auto* in = static_cast<const __m128i*>(src);
  const std::size_t whole = bytes / kStreamingGranule;
  for (std::size_t i = 0; i < whole; ++i)
    _mm_stream_si128(out + i, _mm_loadu_si128(in + i));
  if (const std::size_t rest = bytes % kStreamingGranule; rest > 0) {
    alignas(kStreamingGranule) std::uint8_t tail[kStreamingGranule] = {};
    std::memcpy(tail, static_cast<const std::uint8_t*>(src) + whole * kStreamingGranule, rest);
    _mm_stream_si128(out + whole, _mm_load_si128(reinterpret_cast<const __m128i*>(tail)));
  }
#else
  std::memcpy(dst, src, bytes);
#endif
}

// Orders every streaming store before the stores that follow (the queue's release of a batch):
// on x86 a release store alone does not order non-temporal ones.
inline void streaming_stores_done() noexcept {
#ifdef PANDARCAP_STREAMING_STORES
  _mm_sfence();
#endif
}

}  // namespace pandarcap
