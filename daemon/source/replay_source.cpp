#include "daemon/source/replay_source.hpp"

#include <arpa/inet.h>
#include <spdlog/spdlog.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

#include "core/ipv4.hpp"
#include "daemon/clocks.hpp"

namespace pandarcap {
namespace {

// Sleeps until `deadline_ns` (CLOCK_MONOTONIC) in slices of at most 100 ms, beating the heartbeat
// between them, and returns early on a stop request: a long pause in a recording (or a timestamp
// decades ahead in a crafted file) never holds the thread or silences the watchdog.
void sleep_until_monotonic(std::int64_t deadline_ns, const std::atomic<bool>& stop,
                           std::atomic<std::uint64_t>& heartbeat) noexcept {
  for (;;) {
    const std::int64_t now = monotonic_ns();
    if (now >= deadline_ns || stop.load(std::memory_order_relaxed)) return;
    const std::int64_t until = std::min(deadline_ns, now + 100'000'000);
    const timespec ts{static_cast<time_t>(until / 1'000'000'000),
                      static_cast<long>(until % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);  // EINTR: the loop re-checks
    ReceiveCounters::add(heartbeat, 1);
  }
}

// The longest wait a recording can ask for between two packets at --rate: 1e15 ns (11.6 days).
// Bounding it keeps start + offset far inside int64 whatever the file's timestamps say.
constexpr double kMaxReplayOffsetNs = 1e15;

void copy_text(char (&to)[ReceiveCounters::kDamageTextBytes], std::string_view text) noexcept {
  const std::size_t n = std::min(text.size(), sizeof to - 1);
  std::memcpy(to, text.data(), n);
  to[n] = '\0';
}

}  // namespace

// The reader's damage counts into the health's counters, and the first damage named once.
void ReplaySource::publish_damage(ReceiveCounters& counters) noexcept {
  const CaptureStats& stats = reader_.stats();
  const auto publish = [](std::atomic<std::uint64_t>& counter, std::uint64_t value) {
    if (counter.load(std::memory_order_relaxed) != value)
      counter.store(value, std::memory_order_relaxed);
  };
  publish(counters.capture_records_malformed, stats.malformed);
  publish(counters.capture_chunks_skipped, stats.chunks_skipped);
  publish(counters.capture_packets_skipped, stats.packets_skipped);
  publish(counters.capture_records_damaged, stats.records_damaged);
  if (damage_named_) return;
  if (reader_.first_damage().empty()) return;
  copy_text(counters.capture_first_damage, reader_.first_damage());
  damage_named_ = true;
  counters.capture_damage_named.store(true, std::memory_order_release);
}

ReplaySource::ReplaySource(const ReplayOptions& options)
    : options_(options),
      reader_(options.path, CaptureReader::Options{options.destination_port}),
      size_bytes_(reader_.size_bytes()) {
  if (!reader_.has_endpoints()) {
    // MCAP packets carry no addresses: neither filter can apply. What pandarcapd recorded there
    // is already the sensor's datagrams to its data port (the live receiver's own filters).
    if (options.destination_port || !options.sensor_ip.empty()) {
      spdlog::warn(
          "{}: an MCAP file's packets carry no addresses: {} not applied (every packet in it is "
          "replayed)",
          options.path,
          options.destination_port && !options.sensor_ip.empty() ? "--port and sensor_ip are"
          : options.destination_port                             ? "--port is"
                                                                 : "sensor_ip is");
    }
    return;
  }
  judge_sources_ = true;
  if (!options.sensor_ip.empty()) {
    // A bad address is refused, never ignored: ignoring it would replay every source.
    const auto sensor_ip = parse_ipv4_host_order(options.sensor_ip);
    if (!sensor_ip) {
      throw std::invalid_argument("sensor_ip '" + options.sensor_ip + "' is not an IPv4 address");
    }
    sources_ = SourceLock(*sensor_ip);
    sensor_ip_set_ = true;
  }
}

bool ReplaySource::judge(const CaptureRecord& record, ReceiveCounters& counters) noexcept {
  const SourceLock::Verdict verdict =
      sources_.judge(record.source.ip, record.source.port, record.payload, record.timestamp_ns);
  if (verdict == SourceLock::Verdict::kOtherSensor) ReceiveCounters::add(counters.other_sensor, 1);
  counters.publish_sources(sources_.sensor_source(), sources_.other_source(),
                           sources_.source_changes());
  return verdict == SourceLock::Verdict::kSensor;
}

ReplayResult ReplaySource::run(PacketRing& ring, const std::atomic<bool>& stop,
                               ReceiveCounters& counters, std::atomic<std::uint64_t>& heartbeat) {
  ReplayResult result;
  CaptureRecord record;
  std::optional<std::int64_t> first_record_ns;
  const std::int64_t start_ns = monotonic_ns();
  std::size_t pending = 0;  // filled but not yet published
  std::span<PacketSlot> slots;

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
    publish_damage(counters);
    if ((reader_.stats().records & 1023) == 0)
      bytes_read_.store(reader_.bytes_read(), std::memory_order_relaxed);
    if (status != CaptureStatus::kRecord) {
      result.status = status;
      if (status != CaptureStatus::kEnd) result.error = reader_.error();
      break;
    }
    if (options_.rate) {
      // Recorded pace: packet k goes out (t_k - t_0) / rate after the first.
      publish();
      if (!first_record_ns) first_record_ns = record.timestamp_ns;
      // In double: a crafted file's timestamps may be anything, and their difference must not
      // overflow (nor a huge offset the conversion back to an integer).
      const double offset =
          (static_cast<double>(record.timestamp_ns) - static_cast<double>(*first_record_ns)) /
          *options_.rate;
      sleep_until_monotonic(
          start_ns + static_cast<std::int64_t>(std::clamp(offset, 0.0, kMaxReplayOffsetNs)), stop,
          heartbeat);
      if (stop.load(std::memory_order_relaxed)) {  // stopped while waiting: not sent
        result.stopped = true;
        break;
      }
    }
    // A file never overruns: wait for the decoder to free a slot, before the record is counted
    // as received. A stop during the wait leaves it unsent, as during the pace's wait above, and
    // uncounted (counted first, it was in datagrams_received and in no count after it).
    while (pending == slots.size()) {
      publish();
      slots = ring.reserve(64);
      if (!slots.empty()) break;
      if (stop.load(std::memory_order_relaxed)) break;
      std::this_thread::sleep_for(std::chrono::microseconds(50));
    }
    if (slots.empty()) {
      result.stopped = true;
      break;
    }
    ReceiveCounters::add(counters.datagrams, 1);
    ReceiveCounters::add(counters.bytes, record.udp_payload_length);
    // The sensor's address is IPv4: with sensor_ip set an IPv6 sender is not it; without, the
    // lock judges IPv4 sources only.
    if (judge_sources_ && (record.source.ipv6 ? sensor_ip_set_ : !judge(record, counters))) {
      ReceiveCounters::add(counters.foreign, 1);
      continue;
    }
    PacketSlot& slot = slots[pending++];
    const std::size_t kept = std::min(record.payload.size(), sizeof slot.payload);
    std::memcpy(slot.payload, record.payload.data(), kept);
    slot.length = static_cast<std::uint32_t>(kept);
    slot.original_length =
        std::max(record.udp_payload_length, static_cast<std::uint32_t>(record.payload.size()));
    // A datagram the file holds only part of (snapped: fewer bytes than its UDP length) is not
    // the packet the sensor sent, even when the part happens to have a valid length: it is
    // rejected (bad_length), as the live path rejects a datagram the kernel had to cut.
    slot.truncated = record.udp_payload_length > sizeof slot.payload || record.snapped;
    if (slot.truncated) ReceiveCounters::add(counters.truncated, 1);
    slot.receive_time_ns = record.timestamp_ns;
    slot.source = to_slot_address(record.source);
    slot.destination = to_slot_address(record.destination);
    slot.wire_header_length = 0;
    if (pending == slots.size()) publish();
  }
  publish();
  bytes_read_.store(size_bytes_, std::memory_order_relaxed);
  result.capture = reader_.stats();
  result.first_damage = reader_.first_damage();
  // How the file ended, for the last health record (read by the writer after `capture_end`).
  using End = ReceiveCounters::CaptureEnd;
  End end = End::kWhole;
  if (result.status == CaptureStatus::kTruncated) {
    end = End::kTruncated;
    copy_text(counters.capture_end_text, result.error);
  } else if (result.status == CaptureStatus::kError) {
    end = End::kDamaged;
    copy_text(counters.capture_end_text, result.error);
  } else if (damage_named_) {
    end = End::kDamaged;  // read to its end over damage: the first damage names it
  }
  if (!result.stopped || end != End::kWhole)
    counters.capture_end.store(end, std::memory_order_release);
  return result;
}

}  // namespace pandarcap
