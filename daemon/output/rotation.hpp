// When a recording (pcap, MCAP) starts its next file: once the open one holds `rotate_bytes`, or
// has been open `rotate_seconds` (0: no such limit). SIGHUP and a full chunk index rotate too;
// the recorders handle those.
#pragma once

#include <cstdint>

#include "core/units.hpp"
#include "daemon/clocks.hpp"

namespace pandarcap {

inline bool rotation_due(std::uint64_t file_bytes, std::int64_t opened_monotonic_ns,
                         std::uint64_t rotate_bytes, std::uint32_t rotate_seconds) noexcept {
  return (rotate_bytes != 0 && file_bytes >= rotate_bytes) ||
         (rotate_seconds != 0 &&
          monotonic_ns() - opened_monotonic_ns >= rotate_seconds * kNsPerSecond);
}

}  // namespace pandarcap
