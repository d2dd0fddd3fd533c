// The replay source: feeds a capture (pcap/pcapng, either compressed with zstd, or the packets of
// an MCAP file: CaptureReader) through the same PacketRing the live socket fills, so a recording
// is processed exactly as live data would be, the sensor's source judged as live
// (core/decode/source_lock.hpp: sensor_ip, or the first source to send a packet). An MCAP file's
// packets have no addresses: the port and source filters do not apply to them (a warning says so
// when they are set).
//
// Pace: as fast as the decoder takes it (top speed, the default for files), or the recorded
// pace scaled by `rate` (1 = real time, 2 = twice as fast). Unlike the live receiver, replay
// waits for ring space instead of dropping: a file does not overflow, so nothing is lost.
// The record's capture time becomes the packet's receive time.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>

#include "core/decode/source_lock.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

struct ReplayOptions {
  std::string path;
  std::optional<double> rate;  // empty = top speed
  std::optional<std::uint16_t> destination_port;
  std::string sensor_ip;  // "" = the first source that sends a packet
};

// Damage: a replay reads over what it can (an MCAP file's damaged chunks, skipped by its chunk
// index; pcap records whose headers are damaged), counts it in ReceiveCounters (capture_*) and
// names the first, and says how the file ended there (capture_end) before the source is done:
// the health of a replay that met damage is degraded from then on, to its last record.
struct ReplayResult {
  CaptureStatus status = CaptureStatus::kEnd;  // kEnd, kTruncated or kError
  std::string error;                           // for kTruncated and kError
  std::string first_damage;                    // read over without stopping; "" when none
  CaptureStats capture;
  bool stopped = false;  // stopped early by a signal
};

class ReplaySource {
 public:
  // Opens the file; throws CaptureError naming it when it cannot be read as a capture.
  explicit ReplaySource(const ReplayOptions& options);

  ReplayResult run(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                   std::atomic<std::uint64_t>& heartbeat);

  // How far run() is through the file, in its bytes (updated every 1024 records), and its size:
  // read by the main thread for the progress line.
  std::uint64_t bytes_read() const noexcept { return bytes_read_.load(std::memory_order_relaxed); }
  std::uint64_t size_bytes() const noexcept { return size_bytes_; }

 private:
  // The record's source judged by the lock (IPv4): true when it is the sensor's.
  bool judge(const CaptureRecord& record, ReceiveCounters& counters) noexcept;

  ReplayOptions options_;
  CaptureReader reader_;
  bool damage_named_ = false;
  std::atomic<std::uint64_t> bytes_read_{0};
  std::uint64_t size_bytes_ = 0;
  bool sensor_ip_set_ = false;
  bool judge_sources_ = false;  // the file's records have addresses
  SourceLock sources_{std::nullopt};

  void publish_damage(ReceiveCounters& counters) noexcept;
};

}  // namespace pandarcap
