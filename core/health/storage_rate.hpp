// The outputs' write rates over the last minute, and the hours their disk lasts at that pace
// (health `storage`, docs/storage.md). Pure: the writer hands it the bytes each output has written
// so far and the free space it asked for; nothing here reads a clock or a file.
//
// WriteRateWindow keeps one sample of the cumulative bytes per output a second, in a ring
// allocated with the object (never resized): the rate is what was written between the oldest
// sample at most 60 s old and the newest, over the time between them. Just after the start it
// covers the seconds there are; with fewer than two samples (or under half a second between
// them) the rates are 0.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>

#include "core/health/health.hpp"

namespace pandarcap {

class WriteRateWindow {
 public:
  static constexpr std::int64_t kWindowNs = 60'000'000'000;
  using Bytes = std::array<std::uint64_t, kStorageOutputCount>;

  // The outputs' cumulative bytes at `now_ns` (monotonic). Samples closer than 0.9 s to the last
  // are not kept (a health record written early, when packets stop or start), so the ring always
  // spans the minute.
  void sample(std::int64_t now_ns, const Bytes& cumulative) noexcept;
  // Bytes per second of `output` (kStorageOutputNames order) over the window; 0 when not known.
  double rate(std::size_t output) const noexcept;
  // Seconds the window spans now (0: no rate yet).
  double span_seconds() const noexcept;

 private:
  struct Sample {
    std::int64_t ns = 0;
    Bytes bytes{};
  };
  // The oldest kept sample still inside the window (or the oldest there is).
  const Sample* oldest_in_window() const noexcept;

  static constexpr std::size_t kCapacity = 72;  // > 60 one-second samples plus slack
  std::array<Sample, kCapacity> ring_{};
  std::size_t next_ = 0, count_ = 0;
};

// Free space per output (nothing: not known, or the output is off) and the file system each is
// on (outputs with the same number share one), and the upload backlog, with the window's rates:
// `storage` filled in.
struct StorageInputs {
  std::array<std::optional<std::uint64_t>, kStorageOutputCount> free_bytes{};
  std::array<int, kStorageOutputCount> file_system{};  // an id: equal ids, one file system
  UploadGauges upload;                                 // copied into the gauges as it is
  // The upload backlog's counters (HealthCounters' files_ and bytes_removed_before_upload).
  std::uint64_t files_removed_before_upload = 0, bytes_removed_before_upload = 0;
};
void fill_storage(const WriteRateWindow& window, const StorageInputs& inputs,
                  StorageGauges& storage) noexcept;

// `free_bytes` at `bytes_per_second`, in hours; +infinity when nothing is written.
double hours_left(std::uint64_t free_bytes, double bytes_per_second) noexcept;

}  // namespace pandarcap
