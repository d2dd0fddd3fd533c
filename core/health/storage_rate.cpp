#include "core/health/storage_rate.hpp"

#include <limits>

namespace pandarcap {

void WriteRateWindow::sample(std::int64_t now_ns, const Bytes& cumulative) noexcept {
  if (count_ > 0) {
    const Sample& last = ring_[(next_ + kCapacity - 1) % kCapacity];
    if (now_ns - last.ns < 900'000'000) return;
  }
  ring_[next_] = Sample{now_ns, cumulative};
  next_ = (next_ + 1) % kCapacity;
  if (count_ < kCapacity) ++count_;
}

const WriteRateWindow::Sample* WriteRateWindow::oldest_in_window() const noexcept {
  if (count_ < 2) return nullptr;
  const Sample& newest = ring_[(next_ + kCapacity - 1) % kCapacity];
  // From the oldest kept towards the newest: the first no more than the window before the newest
  // (a little slack: ticks are about, not exactly, a second apart).
  for (std::size_t i = 0; i + 1 < count_; ++i) {
    const Sample& s = ring_[(next_ + kCapacity - count_ + i) % kCapacity];
    if (newest.ns - s.ns <= kWindowNs + 500'000'000) return &s;
  }
  return nullptr;
}

double WriteRateWindow::span_seconds() const noexcept {
  const Sample* oldest = oldest_in_window();
  if (oldest == nullptr) return 0;
  const Sample& newest = ring_[(next_ + kCapacity - 1) % kCapacity];
  return static_cast<double>(newest.ns - oldest->ns) / 1e9;
}

double WriteRateWindow::rate(std::size_t output) const noexcept {
  const Sample* oldest = oldest_in_window();
  const double span = span_seconds();
  if (oldest == nullptr || span < 0.5) return 0;
  const Sample& newest = ring_[(next_ + kCapacity - 1) % kCapacity];
  // A counter taken back (a failed pcap batch's records) reads as nothing written, not negative.
  if (newest.bytes[output] <= oldest->bytes[output]) return 0;
  return static_cast<double>(newest.bytes[output] - oldest->bytes[output]) / span;
}

double hours_left(std::uint64_t free_bytes, double bytes_per_second) noexcept {
  if (!(bytes_per_second > 0)) return std::numeric_limits<double>::infinity();
  return static_cast<double>(free_bytes) / bytes_per_second / 3600.0;
}

void fill_storage(const WriteRateWindow& window, const StorageInputs& inputs,
                  StorageGauges& storage) noexcept {
  storage.written_bytes_per_second_total = 0;
  for (std::size_t i = 0; i < kStorageOutputCount; ++i) {
    storage.written_bytes_per_second[i] = window.rate(i);
    storage.written_bytes_per_second_total += storage.written_bytes_per_second[i];
  }
  // Per file system: its free space over the rate of the outputs on it. The one with the fewest
  // hours is reported; when nothing is written anywhere, the one with the least free space.
  storage.free_known = false;
  storage.free_bytes = 0;
  storage.hours_left = std::numeric_limits<double>::infinity();
  storage.upload = inputs.upload;
  for (std::size_t i = 0; i < kStorageOutputCount; ++i) {
    if (!inputs.free_bytes[i]) continue;
    const std::uint64_t free = *inputs.free_bytes[i];
    double rate = 0;
    for (std::size_t j = 0; j < kStorageOutputCount; ++j) {
      if (inputs.free_bytes[j] && inputs.file_system[j] == inputs.file_system[i])
        rate += storage.written_bytes_per_second[j];
    }
    const double hours = hours_left(free, rate);
    const bool fewer_hours = hours < storage.hours_left;
    const bool same_hours_less_free = hours == storage.hours_left && free < storage.free_bytes;
    if (!storage.free_known || fewer_hours || same_hours_less_free) {
      storage.free_known = true;
      storage.free_bytes = free;
      storage.hours_left = hours;
    }
  }
}

}  // namespace pandarcap
