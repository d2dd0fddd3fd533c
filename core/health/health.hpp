// The daemon's health at one instant: cumulative counters since start-up and current gauges.
// The writer thread fills one every second and renders it as a Prometheus text file and a JSON
// line (core/health/health_format.hpp). Pure data: no I/O here.
//
// Accounting identity (checked by the tests):
//   datagrams_received = packets_accepted + packets_rejected + duplicate_packets
//                        + foreign_datagrams + ring_overruns
// where packets_rejected = sum(rejects) and truncated datagrams are rejected as bad_length.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

#include "core/decode/decoder.hpp"
#include "core/health/latency_histogram.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/status_plausibility.hpp"
#include "core/sensors/packet.hpp"

namespace pandarcap {

enum class HealthState : std::uint8_t {
  kOk,        // packets arriving and decoding
  kNoData,    // no packet for longer than the no-data timeout (a silent sensor, not a hang)
  kDegraded,  // data flows but something is being lost, looks wrong or cannot be written (reason)
  kError,     // the daemon cannot do its job: its socket fails
};
inline constexpr std::size_t kHealthStateCount = 4;
std::string_view to_string(HealthState state) noexcept;  // "ok", "no_data", "degraded", "error"

// Every scalar counter, once: X(field, prometheus_name, help). The HealthCounters fields, the
// Prometheus families (pandarcap_<prometheus_name>_total, HELP = help) and the JSON line's
// "counters" keys (= field) are all generated from this list, in this order, so a counter is
// added in exactly one place. The help text is the field's documentation. Counters that feed the
// health state: receive_errors makes it "error"; kernel_drops, ring_overruns,
// frames_dropped_no_arena, pcap_packets_not_recorded, sequence_lost, points_missing,
// sequence_reordered, sequence_resets, azimuth_gaps, packets_rejected, duplicate_packets,
// outlier_packets, standing_packets, reversed_packets, stream_changes, frameless_packets,
// other_sensor_packets,
// sensor_source_changes, the timestamp counters (invalid_time_packets too), write_errors and
// files_removed_before_upload make it "degraded" while they grow (core/health/health_policy.hpp).
// clang-format off
#define PANDARCAP_HEALTH_COUNTERS(X)                                                               \
  X(datagrams_received, "datagrams_received",                                                      \
    "UDP datagrams delivered by the socket or the replay, from any source")                        \
  X(bytes_received, "received_bytes", "UDP payload bytes received, before truncation")             \
  X(foreign_datagrams, "foreign_datagrams",                                                        \
    "Datagrams from a source other than the sensor's (sensor_ip, or the first to send a packet), " \
    "dropped")                                                                                     \
  X(other_sensor_packets, "other_sensor_packets",                                                  \
    "Valid Pandar packets from a source other than the sensor's: a second sensor on the port. "    \
    "Dropped (also in foreign_datagrams)")                                                         \
  X(sensor_source_changes, "sensor_source_changes",                                                \
    "Times another source was taken as the sensor's, the sensor's having been silent for a "       \
    "second (no sensor_ip)")                                                                       \
  X(truncated_datagrams, "truncated_datagrams",                                                    \
    "Datagrams larger than a ring slot (also rejected as bad_length)")                             \
  X(kernel_drops, "kernel_drops",                                                                  \
    "Datagrams the kernel dropped because the socket buffer was full")                             \
  X(ring_overruns, "ring_overruns",                                                                \
    "Datagrams dropped by the receive thread because the ring was full")                           \
  X(packets_accepted, "packets_accepted", "Packets that passed validation and were decoded")       \
  X(duplicate_packets, "duplicate_packets",                                                        \
    "Copies of a recent packet (same bytes, or a UDP sequence already arrived): not decoded again") \
  X(outlier_packets, "outlier_packets",                                                            \
    "Isolated packets out of the rotation's order: placed by azimuth with their time fixed, or "   \
    "left out of the frames when their azimuth is out of order (points filtered: outlier)")       \
  X(standing_packets, "standing_packets",                                                          \
    "Packets whose azimuth did not move from the packet before: the motor not turning. Left out "  \
    "of the frames (points filtered: standing)")                                                   \
  X(reversed_packets, "reversed_packets",                                                          \
    "Packets of a stream whose azimuth runs backwards (taken as a change after 17): left out of "  \
    "the frames (points filtered: reversed)")                                                      \
  X(stream_changes, "stream_changes",                                                              \
    "Changes of the stream taken (17 packets that follow each other and not the stream: a "        \
    "restart, a gap, a new speed, a clock that stepped, a reversal): the frames in progress end")  \
  X(frameless_packets, "frameless_packets",                                                        \
    "Packets that arrived while no frame had closed for three revolutions' worth of packets")      \
  X(sequence_gaps, "sequence_gaps", "Jumps forward in the UDP sequence number")                    \
  X(sequence_lost, "sequence_lost_packets",                                                        \
    "Packets missing from the UDP sequence (late arrivals forgiven)")                              \
  X(points_missing, "points_missing",                                                              \
    "Channel slots of lost packets (the model's blocks x channels a packet: 400 on a Pandar40P): the UDP sequence's lost packets when the "      \
    "packets carry one, else the azimuth frames lacked (never from the time)")                     \
  X(sequence_duplicates, "sequence_duplicate_packets",                                             \
    "Packets whose UDP sequence number had already arrived")                                       \
  X(sequence_reordered, "sequence_reordered_packets",                                              \
    "Packets that arrived after a later sequence number")                                          \
  X(sequence_resets, "sequence_resets",                                                            \
    "Large jumps in the UDP sequence taken as a sensor restart")                                   \
  X(azimuth_gaps, "azimuth_gaps",                                                                  \
    "Azimuth jumps larger than one packet's worth (packets without a UDP sequence)")               \
  X(static_timestamp_packets, "static_timestamp_packets", "Packets whose time did not advance")    \
  X(backward_timestamp_packets, "backward_timestamp_packets",                                      \
    "Packets whose time went back from the stream's (a glitch, or a clock stepped back)")          \
  X(timestamp_jump_packets, "timestamp_jump_packets",                                              \
    "Packets whose time leapt forward: ahead of the packets after them (a glitch), or the "        \
    "stream's clock more than a second on")                                                        \
  X(invalid_time_packets, "invalid_time_packets",                                                  \
    "Packets with an impossible tail date or microsecond field")                                   \
  X(high_temperature_packets, "high_temperature_packets",                                          \
    "Packets with the high-temperature flag set")                                                  \
  X(return_mode_changes, "return_mode_changes", "Changes of the return mode between packets")      \
  X(points, "points", "Points decoded and kept")                                                   \
  X(points_dropped_frame_full, "points_dropped_frame_full",                                        \
    "Points dropped because the frame arena was full")                                             \
  X(frames_complete, "frames_complete", "Frames cut with a full revolution")                       \
  X(frames_partial, "frames_partial", "Frames cut short (stream start, gap, shutdown)")            \
  X(frames_dropped_no_arena, "frames_dropped_no_arena",                                            \
    "Frames dropped because no arena was free")                                                    \
  X(frames_decimated, "frames_decimated", "Frames skipped on purpose (frame_decimation)")          \
  X(frames_fragment, "frames_fragment",                                                            \
    "Partial frames covering less than output.frames_min_fraction of a revolution: not written")   \
  X(frames_written, "frames_written", "PCD files completed")                                       \
  X(pcap_packets_written, "pcap_packets_written",                                                  \
    "Packets written to pcap files (those since lost with their file: pcap_packets_lost)")        \
  X(pcap_packets_not_recorded, "pcap_packets_not_recorded",                                        \
    "Packets left out of the pcap because the writer was behind (0 without output.pcap)")         \
  X(pcap_packets_not_written, "pcap_packets_not_written",                                          \
    "Packets lost from the pcap to failed writes, or not written to keep space for health")       \
  X(pcap_packets_lost, "pcap_packets_lost",                                                        \
    "Packets written to a recording that vanished (removed while running)")                       \
  X(packets_not_recorded, "packets_not_recorded",                                                  \
    "Packets received but not in a recording on disk: pcap_packets_not_recorded + "                \
    "pcap_packets_not_written + pcap_packets_lost (0 without output.pcap)")                        \
  X(pcap_bytes_written, "pcap_written_bytes", "Bytes written to pcap files")                       \
  X(pcd_bytes_written, "pcd_written_bytes", "Bytes written to PCD files")                          \
  X(files_created, "files_created",                                                                \
    "Files created (frames, recordings, MCAP files, the health's .prom), under temporary names")          \
  X(mcap_messages_written, "mcap_messages_written", "Messages written to MCAP files")             \
  X(mcap_messages_not_written, "mcap_messages_not_written",                                        \
    "Messages lost from MCAP files to failed writes, or not written to keep space for health")    \
  X(mcap_messages_not_recorded, "mcap_messages_not_recorded",                                      \
    "Messages left out of MCAP files because every chunk buffer was in flight (compression or "  \
    "the MCAP disk behind), or packets because no raw batch was free (the writer behind)")        \
  X(mcap_chunks_uncompressed, "mcap_chunks_uncompressed",                                          \
    "MCAP chunks stored uncompressed because compression was a chunk behind")                     \
  X(mcap_messages_lost, "mcap_messages_lost",                                                      \
    "Messages written to an MCAP file that vanished (removed while running)")                     \
  X(mcap_bytes_written, "mcap_written_bytes", "Bytes written to MCAP files")                       \
  X(ptc_requests, "ptc_requests",                                                                  \
    "Requests to the sensor's control port (PTC): calibration, inventory, config, status")         \
  X(ptc_errors, "ptc_errors",                                                                      \
    "PTC requests that failed: refused, timed out, cut short, malformed, or an error code")        \
  X(sensor_status_implausible, "sensor_status_implausible",                                        \
    "Sensor statuses with a field outside its physical range (the field left out)")               \
  X(receive_errors, "receive_errors", "Failed receive calls on the socket")                        \
  X(write_errors, "write_errors", "Failed writes")                                                 \
  X(bytes_not_written, "not_written_bytes", "Bytes lost to failed writes")                         \
  X(output_name_collisions, "output_name_collisions",                                              \
    "Finished files whose name was taken: kept under a _dupN name instead of replacing")           \
  X(files_removed_for_space, "files_removed_for_space",                                            \
    "Files of ours (frames, recordings, MCAP; earlier runs' too) removed, oldest first, to keep "  \
    "output.min_free_bytes / min_free_percent free")                                               \
  X(bytes_removed_for_space, "removed_for_space_bytes",                                            \
    "Bytes of the files removed to keep the free-space floor")                                     \
  X(files_removed_before_upload, "files_removed_before_upload",                                    \
    "Finished files the free-space floor or retention removed before they were uploaded "          \
    "(output.upload): gone from the vehicle, never arrived")                                       \
  X(bytes_removed_before_upload, "removed_before_upload_bytes",                                    \
    "Bytes of the files removed before they were uploaded")                                        \
  X(receive_wakeups, "receive_wakeups",                                                            \
    "Returns of the receive thread from its wait (socket or latency-budget timer)")                \
  X(decode_wakeups, "decode_wakeups", "Returns of the decode thread from its wait on the ring")    \
  X(writer_wakeups, "writer_wakeups",                                                              \
    "Returns of the writer thread from its wait on the decoder's queue")
// clang-format on

struct HealthCounters {
#define PANDARCAP_HEALTH_COUNTER_FIELD(field, prometheus_name, help) std::uint64_t field = 0;
  PANDARCAP_HEALTH_COUNTERS(PANDARCAP_HEALTH_COUNTER_FIELD)
#undef PANDARCAP_HEALTH_COUNTER_FIELD
  // Rendered by hand beside the list: by reason (a Prometheus label, a JSON object), with
  // packets_rejected as the rejects' total.
  std::uint64_t packets_rejected = 0;                               // = sum(rejects)
  std::array<std::uint64_t, kRejectReasonCount> rejects{};          // indexed by RejectReason
  std::array<std::uint64_t, kFilterReasonCount> filtered_points{};  // indexed by FilterReason
  // The CPU the files_created took to create, in microseconds (JSON); Prometheus has it in
  // seconds, its base unit.
  std::uint64_t file_create_cpu_us = 0;
};

#define PANDARCAP_HEALTH_COUNTER_ONE(field, prometheus_name, help) +1
// The number of scalar counters in PANDARCAP_HEALTH_COUNTERS.
inline constexpr std::size_t kHealthCounterCount =
    0 PANDARCAP_HEALTH_COUNTERS(PANDARCAP_HEALTH_COUNTER_ONE);
#undef PANDARCAP_HEALTH_COUNTER_ONE

// What the sensor says about itself over its control port (PTC), polled every
// sensor.status_interval_seconds by a thread off the packet path (daemon/ptc/). The values are
// reported only while fresh: a status older than 3 intervals is stale, and says so.
struct SensorStatusGauges {
  bool polled = false;          // polling is on (a live sensor with sensor_ip, interval > 0)
  bool available = false;       // a status has arrived since start-up
  bool stale = false;           // the last status is older than 3 polling intervals
  double age_seconds = -1;      // since the last status arrived; -1: none yet
  double interval_seconds = 0;  // sensor.status_interval_seconds
  bool clock_source_known = false;
  bool clock_source_ptp = false;  // the sensor's configured clock source is PTP (else GPS)
  // The last status's fields (ptc::SensorStatus, in units).
  double uptime_seconds = 0;
  double motor_rpm = 0;
  std::array<double, 8> temperatures_celsius{};  // in ptc::kTemperatureNames order
  bool gps_pps_locked = false;
  bool gps_nmea_locked = false;
  std::uint8_t ptp_state = 0;     // ptc::PtpState: 0 free run, 1 tracking, 2 locked, 3 frozen
  bool ptp_offset_known = false;  // the sensor answers PTP diagnostics (0x06)
  double ptp_offset_seconds = 0;  // its offset from the PTP master
  // The last status's fields outside their physical range (core/ptc/status_plausibility.hpp):
  // left out of the record, and said in `implausible_reason`.
  std::uint32_t implausible = 0;
  std::string implausible_reason;
};

// The status's fields into `gauges`, in units, with which of them are implausible (the reason
// text rewritten in place, keeping its capacity). The freshness and PTP fields are the caller's.
inline void set_status_fields(SensorStatusGauges& gauges, const ptc::SensorStatus& status) {
  gauges.uptime_seconds = status.uptime_s;
  gauges.motor_rpm = status.motor_rpm;
  for (std::size_t i = 0; i < ptc::kTemperatureCount; ++i)
    gauges.temperatures_celsius[i] = status.temperature_centi_c[i] / 100.0;
  gauges.gps_pps_locked = status.gps_pps_locked == 1;
  gauges.gps_nmea_locked = status.gps_nmea_locked == 1;
  gauges.ptp_state = status.ptp_state;
  gauges.implausible = ptc::implausible_fields(status);
  gauges.implausible_reason.clear();
  ptc::describe_implausible(status, gauges.implausible, gauges.implausible_reason);
}

// Who the sensor is and where the angles come from: found at start-up, constant after. Empty
// strings where the sensor was not asked or did not answer.
struct SensorIdentity {
  std::string serial;
  std::string firmware;            // the sensor firmware version
  std::string calibration_source;  // "sensor", "file", "nominal" or "recording" (a replay)
};

// What the outputs write and how long their disk lasts at that pace (docs/storage.md). The
// outputs, in this order: frames (PCD files), pcap (raw recordings), mcap, health (health.jsonl
// lines; the .prom file is replaced, it does not grow).
inline constexpr std::size_t kStorageOutputCount = 4;
inline constexpr std::array<std::string_view, kStorageOutputCount> kStorageOutputNames = {
    "frames", "pcap", "mcap", "health"};

// The finished files still waiting in the upload directories (output.upload: raw/ and mcap/, and
// frames/ with output.upload_frames; docs/deploy.md), as the last pass over them found them:
// what systemd/pandarcap-upload@.service will move (no .part, no hidden file, nothing not ours).
// Counted whether or not output.upload is on (`enabled` says which): without it they are the
// recordings kept on the vehicle.
struct UploadGauges {
  bool enabled = false;  // output.upload
  bool known = false;    // a pass over the directories has finished
  std::uint64_t backlog_bytes = 0, backlog_files = 0;
  // Seconds since the oldest of them was finished (its modification time, by the host's clock);
  // 0 when there is none, and never below 0 (a clock set back).
  double oldest_seconds = 0;
  // The last file the floor or retention removed before it was uploaded (its name, no
  // directory; cut to fit), and which of the two removed it: the state's reason names it.
  char last_removed[128] = {};
  bool last_removed_by_floor = false;
};

struct StorageGauges {
  // Free bytes (statvfs f_bavail) on the output file system that fills first at the current
  // rates (with every output on one file system, simply its free space); unknown when no output
  // file system could be asked.
  bool free_known = false;
  std::uint64_t free_bytes = 0;
  // Bytes written per second over the last minute (fewer seconds just after the start), by output
  // (kStorageOutputNames order), and their sum.
  std::array<double, kStorageOutputCount> written_bytes_per_second{};
  double written_bytes_per_second_total = 0;
  // Hours until that file system is full at the last minute's pace: its free bytes over the rate
  // of the outputs on it (the least over file systems). +infinity when nothing is written there,
  // or the free space is unknown (JSON null; the .prom says +Inf).
  double hours_left = std::numeric_limits<double>::infinity();
  UploadGauges upload;
};

// Where the health files are while their own directory cannot be written (a disk gone read-only
// or failing): health.fallback_directory. Inactive (the strings empty) while they are home.
struct HealthFallbackGauges {
  bool active = false;
  std::string directory;  // where they are written now
  std::string error;      // why their own directory cannot take them
};

struct HealthGauges {
  double rpm_tail = 0;       // mean motor speed reported in the tails over the last second
  double rpm_measured = 0;   // from azimuth progression over packet time, last second
  double frame_rate_hz = 0;  // complete frames cut in the last second
  // Packets per second by the sensor's own clock over the last second (StreamStats'
  // rate_packets / rate_time_ns); 0 while unknown. The sensor sends a fixed rate
  // (core/sensors/sensor_model.hpp): more is two streams on one port, less is loss.
  double packet_rate_hz = 0;
  // The sensor's source and, when one sent valid packets, another's (core/decode/source_lock.hpp),
  // as pack_ipv4_source (core/ipv4.hpp); 0: none.
  std::uint64_t sensor_source = 0;
  std::uint64_t other_sensor_source = 0;
  std::string return_mode;  // "last", "strongest", "dual", or "" before the first packet
  // The last impossible tail time's first field out of range and its value ("month 31",
  // "microseconds 1200000"; core/decode/packet_time.hpp), "" before one.
  std::string last_invalid_time;
  bool high_temperature = false;  // the last packet's flag
  // The sensor's clock minus the host's: the last accepted packet's time (its tail) minus the
  // kernel's receive time of it (a replay: the recording's capture time). A synchronised sensor
  // reads a fraction of a millisecond below 0 (the packet is sent after its blocks fired);
  // one that has lost its clock reads years. Unknown before the first packet with a receive time.
  bool sensor_clock_offset_known = false;
  double sensor_clock_offset_seconds = 0;
  double seconds_since_last_packet = -1;  // -1 before the first packet
  double uptime_seconds = 0;
  double receive_wakeups_per_second = 0;  // over the last second
  double decode_wakeups_per_second = 0;
  double writer_wakeups_per_second = 0;
  SensorStatusGauges sensor_status;
  StorageGauges storage;
  HealthFallbackGauges health_fallback;
  // Problems that hold until they end, not counters that grow (daemon/output/standing_problems):
  // a replay that met damage in its file, a live view that cannot listen. "" when none.
  std::string standing;
  HealthState state = HealthState::kNoData;
  std::string reason;  // one line saying why the state is not ok ("" when ok)
};

// The live view (daemon/live/, [live] foxglove): its viewers now and what they were sent or not.
struct LiveViewHealth {
  std::uint64_t clients = 0;
  std::uint64_t messages_sent = 0;
  // A viewer's queue was full (one per viewer and message), or a frame was replaced by the next
  // before the server thread took it.
  std::uint64_t messages_dropped = 0;
  bool listening = false;  // false: its port could not be bound yet (retrying)
};

struct HotPathAllocations {
  std::uint64_t receive = 0, decode = 0, writer = 0;
  std::uint64_t total() const noexcept { return receive + decode + writer; }
};

struct HealthSnapshot {
  std::int64_t unix_time_ns = 0;   // when it was taken (CLOCK_REALTIME)
  std::string sensor;              // the `sensor` label (config: health.sensor_name)
  std::string version;             // pandarcap version, for the _build_info gauge
  std::string decoder;             // decoder target in use ("avx512", "scalar", ...), likewise
  SensorIdentity sensor_identity;  // the pandarcap_sensor_info gauge's labels
  HealthCounters counters;
  HealthGauges gauges;
  // Whether points were decoded and frames cut: false when nothing consumes them (output.frames
  // and output.mcap off; the decoder then does only what the health needs). Then the counters
  // points, points_dropped_frame_full, frames_complete, frames_partial, frames_decimated,
  // frames_fragment, points_missing and frameless_packets, the filtered points by reason and the
  // frame_rate_hz gauge are left out of
  // both renderings (not counted is not 0); every other counter, frames_dropped_no_arena and
  // frames_written included (no frame is cut, so none is lost or written), keeps its meaning.
  bool points_counted = true;
  // Kernel receive timestamp -> decoded, since start-up; empty when replaying a file.
  LatencyHistogram latency;
  // Kernel receive timestamp of the packet that completed a frame -> its PCD renamed into place,
  // since start-up: what a user waits for a frame. Empty when replaying or not writing frames.
  LatencyHistogram frame_latency;
  // Heap allocations made by the receive, decode and writer loops after warm-up; absent where
  // they cannot be counted (sanitizer builds).
  std::optional<HotPathAllocations> hot_path_allocations;
  // Present while the live view is on.
  std::optional<LiveViewHealth> live;
};

}  // namespace pandarcap
