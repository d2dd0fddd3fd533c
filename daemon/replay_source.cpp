#include "daemon/replay_source.hpp"

#include <arpa/inet.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

#include "daemon/clocks.hpp"

namespace pandarcap {
namespace {

void sleep_until_monotonic(std::int64_t deadline_ns) noexcept {
  const timespec ts{static_cast<time_t>(deadline_ns / 1'000'000'000),
                    static_cast<long>(deadline_ns % 1'000'000'000)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

ReplaySource::ReplaySource(const ReplayOptions& options)
    : options_(options), reader_(options.path, CaptureReader::Options{options.destination_port}) {
  if (!options.sensor_ip.empty()) {
    in_addr address{};
    if (inet_pton(AF_INET, options.sensor_ip.c_str(), &address) == 1) {
      sensor_ip_ = ntohl(address.s_addr);
    }
  }
}

ReplayResult ReplaySource::run(ringbuf::PacketRing& ring, const std::atomic<bool>& stop,
                               ReceiveCounters& counters, std::atomic<std::uint64_t>& heartbeat) {
  ReplayResult result;
  CaptureRecord record;
  std::optional<std::int64_t> first_record_ns;
  const std::int64_t start_ns = monotonic_ns();
  std::size_t pending = 0;  // filled but not yet published
  std::span<ringbuf::PacketSlot> slots;

  const auto publish = [&] {
    if (pending == 0) return;
    ring.publish(pending);
    ring.notify();
    pending = 0;
    slots = {};
  };

  for (;;) {
    ReceiveCounters::add(heartbeat, 1);
    if (stop.load(std::memory_order_relaxed)) {
      result.stopped = true;
      break;
    }
    const CaptureStatus status = reader_.next(record);
    if (status != CaptureStatus::kRecord) {
      result.status = status;
      if (status == CaptureStatus::kError) result.error = reader_.error();
      break;
    }
    if (options_.rate) {
      // Recorded pace: packet k goes out (t_k - t_0) / rate after the first.
      publish();
      if (!first_record_ns) first_record_ns = record.timestamp_ns;
      const double offset =
          static_cast<double>(record.timestamp_ns - *first_record_ns) / *options_.rate;
      sleep_until_monotonic(start_ns + static_cast<std::int64_t>(std::max(0.0, offset)));
    }
    ReceiveCounters::add(counters.datagrams, 1);
    ReceiveCounters::add(counters.bytes, record.udp_payload_length);
    if (sensor_ip_ && record.source.ip != *sensor_ip_) {
      ReceiveCounters::add(counters.foreign, 1);
      continue;
    }
    // A file never overruns: wait for the decoder to free a slot.
    while (pending == slots.size()) {
      publish();
      slots = ring.reserve(64);
      if (!slots.empty()) break;
      if (stop.load(std::memory_order_relaxed)) break;
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    if (slots.empty()) continue;  // stopping
    ringbuf::PacketSlot& slot = slots[pending++];
    const std::size_t kept = std::min(record.payload.size(), sizeof slot.payload);
    std::memcpy(slot.payload, record.payload.data(), kept);
    slot.length = static_cast<std::uint32_t>(kept);
    slot.truncated = record.udp_payload_length > sizeof slot.payload;
    if (slot.truncated || record.snapped) ReceiveCounters::add(counters.truncated, 1);
    slot.receive_time_ns = record.timestamp_ns;
    slot.source = sockaddr_in{};
    slot.source.sin_family = AF_INET;
    slot.source.sin_addr.s_addr = htonl(record.source.ip);
    slot.source.sin_port = htons(record.source.port);
    if (pending == slots.size()) publish();
  }
  publish();
  result.capture = reader_.stats();
  return result;
}

}  // namespace pandarcap
