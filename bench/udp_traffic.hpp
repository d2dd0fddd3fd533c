// Loopback traffic for the benchmark harness: a paced packet generator (sendmmsg) of any supported
// sensor model, and the two reference receivers the daemon is compared with (recvmmsg into a
// buffer, and recvfrom one packet per call, the vendor SDKs' way).
//
// By default every generated packet is a 1266-byte Pandar40P packet whose 4-byte UDP sequence the
// generator writes itself (0, 1, 2, ...), so a receiver's loss is exact: sent - received, and a
// daemon counts any gap. Without it the packets are the sensor's plain 1262 bytes. The other
// models' packets (TrafficSource::synthetic_model) carry the sequence the same way: appended to
// the Pandar64's 1194 bytes, inside the XT's and the QT128's tails.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/sensors/model_access.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "core/sim/synthetic_sensor.hpp"

namespace pandarcap::bench {

// The bytes of a packet the generator writes itself, per packet: a run of the tail from `offset`
// to the body's end holding the µs timestamp and the UTC date (and, for the XT and the QT128, the
// UDP sequence; for the QT128 the tail's CRC, which covers them). The bytes around the fields are
// the body's. The Pandar40P's: bytes 1250-1261, µs then return mode, factory, date.
// Where the generator writes each packet's time (core/sensors/model_access.hpp).
using TailFields = TimeRun;

// Packet bodies to send (the 40P's and the Pandar64's: the bytes before the sequence; the others':
// the whole datagram), cycled in order, and when each is due in the sensor's time: body k at
// offsets_ns[k] from the first, the cycle repeating every loop_ns. The generator writes every
// packet's tail time from these (a clock that runs), so the cycle is one continuous rotation whose
// packet times keep rising.
struct TrafficSource {
  std::vector<std::vector<std::uint8_t>> bodies;
  std::vector<std::int64_t> offsets_ns;
  std::int64_t loop_ns = 0;
  std::string description;
  SensorModelId model = SensorModelId::kPandar40P;
  TailFields tail = time_run<Pandar40P>({});  // the 40P's (its tail sits at fixed offsets)
  // The sensor's own packet rate (0: not known, a capture's).
  double packets_per_second = 0;

  // A datagram's size as sent: the body, and the appended sequence when asked for.
  std::size_t datagram_bytes(bool udp_sequence) const noexcept {
    return tail.offset + tail.bytes + (udp_sequence && !tail.sequence_at ? 4 : 0);
  }

  // One second of the simulated sensor (`sensor.rpm`, `sensor.return_mode`): 3600 packets in
  // dual return, 1800 in single, whatever the RPM (the firing rate is fixed; the azimuth step
  // per block grows with the RPM). A second of packets is not quite a whole number of
  // revolutions (3600 x 277.8 us = 1.00008 s: 10.0008 turns at 600 RPM), so where the cycle
  // joins, the azimuth steps 0.29 deg short of its usual step (0.58 deg at 1200 RPM): well inside
  // what a receiver takes for one rotation (pandarcapd: 2 deg + 2 %), and the running clock
  // (loop_ns) keeps the times exact, but the azimuths fall that much behind the clock at each
  // join. Its sequence settings are ignored: the generator writes them.
  static TrafficSource synthetic(const SyntheticSensorConfig& sensor);
  // One second of a simulated `model` (AnyModelSensor) at `rpm` in `mode`, its loop joined the
  // same way: Model::packets_per_second packets (the Pandar40P: synthetic() above, byte for byte).
  // `udp_sequence` decides the QT128's layout (its sequence flag); the XT always carries one and
  // the 40P's and the Pandar64's are appended by the generator when its options ask. Throws
  // std::invalid_argument for a speed or mode the model does not have.
  static TrafficSource synthetic_model(SensorModelId model, int rpm, ReturnMode mode,
                                       bool udp_sequence);
  // Every valid Pandar40P packet of a pcap/pcapng file (its own sequence, if any, is replaced),
  // at its tail time's offset from the first's (its record time where the tail's is not valid).
  // Throws std::runtime_error when the file has none.
  static TrafficSource from_capture(const std::string& path);
};

struct GeneratorOptions {
  std::string destination_ip = "127.0.0.1";  // never anything the user did not give
  // The network namespace the sending sockets are made in (/run/netns/NAME; "" = this process's):
  // zero-loss --veth sends from the far end's namespace.
  std::string network_namespace;
  std::uint16_t port = 2368;
  double rate_pps = 3600;
  double seconds = 10;
  int batch = 32;  // datagrams per sendmmsg
  // The first packet's UDP sequence (and place in the source's bodies): a second run that
  // continues a first one's stream starts at the first one's `sent`.
  std::uint64_t first_sequence = 0;
  // false: 1262-byte packets, loss only from the receiver's count. The 40P's and the Pandar64's
  // (the XT's and the QT128's sequence is the source's: TailFields::sequence_at).
  bool udp_sequence = true;
  // The sensor time of the first packet (Unix ns); 0: the host's clock when sending starts. Every
  // packet's tail carries its own time from there (TrafficSource's offsets), so the stream's
  // clock runs and agrees with the host's.
  std::int64_t clock_start_unix_ns = 0;
  // Bursts: every `burst_every_s`, `burst_ms` at `burst_factor` x the rate.
  double burst_factor = 1;
  double burst_ms = 0;
  double burst_every_s = 1;
  // Extra traffic mixed in, as fractions of the valid packets: datagrams from 127.0.0.2 (foreign)
  // and random-length random bytes (malformed).
  double foreign_fraction = 0;
  double malformed_fraction = 0;
  // Faults of a vehicle day, as fractions of the valid packets: a copy of the packet just sent
  // (a switch loop, a mirror port), and a packet whose tail time is wrong (minutes back or
  // ahead: an isolated clock glitch). Both are still valid packets; a daemon counts them as
  // duplicate_packets and outlier_packets.
  double duplicate_fraction = 0;
  double glitch_fraction = 0;
};

struct GeneratorResult {
  std::uint64_t sent = 0;  // valid packets, sequences first_sequence .. first_sequence+sent-1
  std::uint64_t foreign_sent = 0;
  std::uint64_t malformed_sent = 0;
  std::uint64_t duplicates_sent = 0;  // copies, besides `sent`
  std::uint64_t glitches_sent = 0;    // among `sent`
  std::uint64_t send_errors = 0;      // sendmmsg failures other than a full socket buffer
  double seconds = 0;
  double achieved_pps = 0;  // valid packets per second actually sent
  double cpu_seconds = 0;   // the sending thread's CPU time (CLOCK_THREAD_CPUTIME_ID)
};

// Why `options` cannot be sent, or nothing when they can: a destination that is not an IPv4
// address, or foreign traffic (sent from 127.0.0.2) towards a destination outside 127.0.0.0/8,
// which it could not reach. Command lines check this first, to report a usage error.
std::optional<std::string> generator_options_problem(const GeneratorOptions& options);

// Sends for `options.seconds`, paced in batches against CLOCK_MONOTONIC. Throws
// std::runtime_error with generator_options_problem(), or when the socket cannot be set up.
GeneratorResult run_generator(const TrafficSource& source, const GeneratorOptions& options);

// A reference receiver on `bind_ip` (127.0.0.1; with zero-loss --veth the near end's address): a
// thread that receives and counts, nothing else.
class ReferenceReceiver {
 public:
  enum class Kind { kRecvmmsg, kRecvfrom };
  ReferenceReceiver(Kind kind, std::uint64_t receive_buffer_bytes,
                    const std::string& bind_ip = "127.0.0.1");
  ~ReferenceReceiver();
  ReferenceReceiver(const ReferenceReceiver&) = delete;
  ReferenceReceiver& operator=(const ReferenceReceiver&) = delete;

  std::uint16_t port() const noexcept { return port_; }
  int receive_buffer_granted() const noexcept { return granted_; }
  // Waits until nothing arrived for `quiet_ms`, then stops the thread.
  void drain_and_stop(int quiet_ms);
  std::uint64_t received() const noexcept { return received_.load(std::memory_order_relaxed); }
  std::uint64_t kernel_drops() const;  // SO_MEMINFO
  double cpu_seconds() const noexcept { return cpu_seconds_; }

 private:
  void run();
  Kind kind_;
  int fd_ = -1;
  std::uint16_t port_ = 0;
  int granted_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> received_{0};
  double cpu_seconds_ = 0;
  std::thread thread_;
};

}  // namespace pandarcap::bench
