// Where the daemon's packets come from, opened before READY: the live socket (or the packet
// ring, input.receiver), the socket the built-in simulated sensor sends to, or a capture file
// replayed.
//
// Opening is where a source fails (a port in use, a missing file): before any thread starts, so
// the start can report it with an exit status. run() is the source thread's body. Which source a
// run uses, and its options, are the lifecycle's choice (pandarcapd's open_source(), with
// daemon_options.hpp); this side knows nothing of the configuration.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "core/sim/synthetic_sensor.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/source/packet_ring_receiver.hpp"
#include "daemon/source/replay_source.hpp"
#include "daemon/source/simulated_sender.hpp"
#include "daemon/source/udp_receiver.hpp"

namespace pandarcap {

class PacketSource {
 public:
  // The sensor's packets on a socket bound as `options` says. Throws std::exception (a port in
  // use, an address this host does not have).
  static std::unique_ptr<PacketSource> live(const UdpReceiverOptions& options);
  // A socket as live, and the built-in simulated sensor `sensor` sending to it over loopback.
  static std::unique_ptr<PacketSource> simulated(const UdpReceiverOptions& options,
                                                 SensorModelId model,
                                                 const SyntheticSensorConfig& sensor);
  // A capture file. Throws CaptureError for a capture that cannot be read.
  static std::unique_ptr<PacketSource> replay(const ReplayOptions& options);

  const char* thread_name() const noexcept { return replay_ ? "pc-replay" : "pc-receive"; }
  bool simulated() const noexcept { return simulator_ != nullptr; }

  // The source thread (not for read_by_decoder(): that source ends at once, with an error
  // logged): receives (or replays) into `ring` until `stop`, or the end of the file; then sets
  // `done`.
  void run(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
           std::atomic<std::uint64_t>& heartbeat, std::atomic<bool>& done);
  // The packet ring is read by the decode thread itself (DecodeWorker::run_inline), not by a
  // thread of its own: the kernel's ring of blocks is the queue between receive and decode, so
  // a block wakes one thread, not a receive thread that then wakes the decoder. At a sensor's
  // rate each wake costs more than the packets it hands on (docs/performance.md).
  bool read_by_decoder() const noexcept { return ring_receiver_ != nullptr; }
  // read_by_decoder() only: one turn of the receive loop, on the decode thread, until `stop` is
  // set and what came before it is taken; then sets `done`.
  ReceiveTurn receive_turn(PacketRing& ring, const std::atomic<bool>& stop,
                           ReceiveCounters& counters, std::atomic<std::uint64_t>& heartbeat,
                           std::atomic<bool>& done);
  // read_by_decoder() only: how full the kernel's ring is, for the decode thread's waits for
  // the writer (PacketRingReceiver::blocks_waiting).
  std::uint32_t blocks_waiting() const noexcept { return ring_receiver_->blocks_waiting(); }
  std::uint32_t block_count() const noexcept { return ring_receiver_->block_count(); }
  // read_by_decoder() only: the arrivals the kernel has handed over, noted for the health while
  // the decode thread waits for the writer (PacketRingReceiver::note_arrivals).
  void note_arrivals(ReceiveCounters& counters) noexcept {
    ring_receiver_->note_arrivals(counters);
  }
  // The simulator thread (simulated() only): sends until `stop`.
  void run_simulator(const std::atomic<bool>& stop);

  // After run(): how the replay ended (replays only).
  bool replayed() const noexcept { return replay_ != nullptr; }
  const ReplayResult& replay_result() const noexcept { return replay_result_; }
  // The replay's file, for its progress while run() reads it; null for a live source.
  const ReplaySource* replay_source() const noexcept { return replay_.get(); }

 private:
  PacketSource() = default;

  std::unique_ptr<UdpReceiver> receiver_;
  std::unique_ptr<PacketRingReceiver> ring_receiver_;  // instead of receiver_ (packet_ring)
  std::unique_ptr<ReplaySource> replay_;
  std::unique_ptr<SimulatedSender> simulator_;
  ReplayResult replay_result_;
};

}  // namespace pandarcap
