// The daemon's health at one instant: cumulative counters since start-up and current gauges.
// The writer thread fills one every second and renders it as a Prometheus text file and a JSON
// line (core/health_format.hpp). Pure data: no I/O here.
//
// Accounting identity (checked by the tests):
//   datagrams_received = packets_accepted + packets_rejected + foreign_datagrams + ring_overruns
// where packets_rejected = sum(rejects) and truncated datagrams are rejected as bad_length.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "decoder.hpp"
#include "latency_histogram.hpp"
#include "packet.hpp"

namespace pandarcap {

enum class HealthState : std::uint8_t {
  kOk,        // packets arriving and decoding
  kNoData,    // no packet for longer than the no-data timeout (a silent sensor, not a hang)
  kDegraded,  // data flows but something is being lost, looks wrong or cannot be written (reason)
  kError,     // the daemon cannot do its job: its socket fails
};
inline constexpr std::size_t kHealthStateCount = 4;
std::string_view to_string(HealthState state) noexcept;  // "ok", "no_data", "degraded", "error"

struct HealthCounters {
  // Receive side.
  std::uint64_t datagrams_received = 0;   // every datagram the socket (or replay) delivered
  std::uint64_t bytes_received = 0;       // their UDP payload bytes (before truncation)
  std::uint64_t foreign_datagrams = 0;    // from a source other than sensor_ip: dropped
  std::uint64_t truncated_datagrams = 0;  // larger than a ring slot (MSG_TRUNC)
  std::uint64_t kernel_drops = 0;         // socket buffer overflows reported by the kernel
  std::uint64_t ring_overruns = 0;        // ring full: datagram dropped by the receive thread
  std::uint64_t receive_errors = 0;       // recvmmsg failures (not timeouts): state "error"
  // Decode side.
  std::uint64_t packets_accepted = 0;
  std::uint64_t packets_rejected = 0;                       // = sum(rejects)
  std::array<std::uint64_t, kRejectReasonCount> rejects{};  // indexed by RejectReason
  std::uint64_t sequence_gaps = 0;
  std::uint64_t sequence_lost = 0;
  std::uint64_t sequence_duplicates = 0;
  std::uint64_t sequence_reordered = 0;
  std::uint64_t sequence_resets = 0;
  std::uint64_t azimuth_gaps = 0;  // without a UDP sequence: azimuth jumped more than expected
  std::uint64_t static_timestamp_packets = 0;    // packet time did not advance
  std::uint64_t backward_timestamp_packets = 0;  // packet time went back
  std::uint64_t timestamp_jump_packets = 0;      // packet time leapt forward by more than 1 s
  std::uint64_t invalid_time_packets = 0;        // bad tail date or microseconds
  std::uint64_t high_temperature_packets = 0;
  std::uint64_t return_mode_changes = 0;
  std::uint64_t points = 0;
  std::array<std::uint64_t, kFilterReasonCount> filtered_points{};  // indexed by FilterReason
  std::uint64_t points_dropped_frame_full = 0;
  // Frames.
  std::uint64_t frames_complete = 0;
  std::uint64_t frames_partial = 0;
  std::uint64_t frames_dropped_no_arena = 0;     // no free arena when the frame began
  std::uint64_t frames_dropped_writer_busy = 0;  // writer queue full (slow disk): not written
  std::uint64_t frames_decimated = 0;            // skipped on purpose (frame_decimation)
  std::uint64_t frames_fragment = 0;  // partial, under output.frames_min_fraction: not written
  std::uint64_t frames_written = 0;   // PCD files completed
  // Writer.
  std::uint64_t pcap_packets_written = 0;
  std::uint64_t pcap_packets_not_recorded = 0;  // no free raw batch (writer behind): not in pcap
  std::uint64_t pcap_packets_not_written = 0;   // lost to failed writes (a full disk)
  std::uint64_t pcap_bytes_written = 0;
  std::uint64_t pcd_bytes_written = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t bytes_not_written = 0;
  // A finished file whose name was taken (which the naming rules should make impossible): kept
  // under a free "_dupN" name, never replacing the other.
  std::uint64_t output_name_collisions = 0;
  // Returns from each thread's wait (a sleep on the socket, the ring or the timer): what the
  // latency budget saves, visible in the field.
  std::uint64_t receive_wakeups = 0;
  std::uint64_t decode_wakeups = 0;
  std::uint64_t writer_wakeups = 0;
};

struct HealthGauges {
  double rpm_tail = 0;            // mean motor speed reported in the tails over the last second
  double rpm_measured = 0;        // from azimuth progression over packet time, last second
  double frame_rate_hz = 0;       // complete frames cut in the last second
  std::string return_mode;        // "last", "strongest", "dual", or "" before the first packet
  bool high_temperature = false;  // the last packet's flag
  double seconds_since_last_packet = -1;  // -1 before the first packet
  double uptime_seconds = 0;
  double receive_wakeups_per_second = 0;  // over the last second
  double decode_wakeups_per_second = 0;
  double writer_wakeups_per_second = 0;
  HealthState state = HealthState::kNoData;
  std::string reason;  // one line saying why the state is not ok ("" when ok)
};

struct HotPathAllocations {
  std::uint64_t receive = 0, decode = 0, writer = 0;
  std::uint64_t total() const noexcept { return receive + decode + writer; }
};

struct HealthSnapshot {
  std::int64_t unix_time_ns = 0;  // when it was taken (CLOCK_REALTIME)
  std::string sensor;             // the `sensor` label (config: health.sensor_name)
  std::string version;            // pandarcap version, for the _build_info gauge
  std::string decoder;            // decoder target in use ("avx512", "scalar", ...), likewise
  HealthCounters counters;
  HealthGauges gauges;
  // Kernel receive timestamp -> decoded, since start-up; empty when replaying a file.
  LatencyHistogram latency;
  // Kernel receive timestamp of the packet that completed a frame -> its PCD renamed into place,
  // since start-up: what a user waits for a frame. Empty when replaying or not writing frames.
  LatencyHistogram frame_latency;
  // Heap allocations made by the receive, decode and writer loops after warm-up; absent where
  // they cannot be counted (sanitizer builds).
  std::optional<HotPathAllocations> hot_path_allocations;
};

}  // namespace pandarcap
