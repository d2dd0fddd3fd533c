#include "daemon/source/packet_source.hpp"

#include <spdlog/spdlog.h>

namespace pandarcap {

std::unique_ptr<PacketSource> PacketSource::live(const UdpReceiverOptions& options) {
  std::unique_ptr<PacketSource> source(new PacketSource);
  if (options.packet_ring) {
    source->ring_receiver_ = std::make_unique<PacketRingReceiver>(options);
  } else {
    source->receiver_ = std::make_unique<UdpReceiver>(options);
  }
  return source;
}

std::unique_ptr<PacketSource> PacketSource::simulated(const UdpReceiverOptions& options,
                                                      SensorModelId model,
                                                      const SyntheticSensorConfig& sensor) {
  std::unique_ptr<PacketSource> source = live(options);
  const std::uint16_t port =
      source->receiver_ ? source->receiver_->bound_port() : source->ring_receiver_->bound_port();
  source->simulator_ =
      std::make_unique<SimulatedSender>(model, sensor, "127.0.0.1", "127.0.0.1", port);
  spdlog::info("simulated sensor: {}, {} RPM, {} return{}, sending to 127.0.0.1:{}",
               display_name(model), sensor.rpm, to_string(sensor.return_mode),
               sensor.udp_sequence ? ", UDP sequence" : "", port);
  return source;
}

std::unique_ptr<PacketSource> PacketSource::replay(const ReplayOptions& options) {
  std::unique_ptr<PacketSource> source(new PacketSource);
  source->replay_ = std::make_unique<ReplaySource>(options);
  return source;
}

void PacketSource::run(PacketRing& ring, const std::atomic<bool>& stop, ReceiveCounters& counters,
                       std::atomic<std::uint64_t>& heartbeat, std::atomic<bool>& done) {
  if (replay_) {
    replay_result_ = replay_->run(ring, stop, counters, heartbeat);
  } else if (ring_receiver_) {
    // The packet ring has no thread of its own: the decoder reads it (read_by_decoder(),
    // receive_turn()), one block into a ring it has just emptied. A loop here would find the
    // ring full and spin, so a caller that gets this wrong gets an error and an ended source.
    spdlog::error("internal: the packet ring is read by the decode thread, not by run()");
  } else {
    receiver_->run(ring, stop, counters, heartbeat);
  }
  // release: everything the source published happens before the decoder sees "done".
  done.store(true, std::memory_order_release);
}

ReceiveTurn PacketSource::receive_turn(PacketRing& ring, const std::atomic<bool>& stop,
                                       ReceiveCounters& counters,
                                       std::atomic<std::uint64_t>& heartbeat,
                                       std::atomic<bool>& done) {
  const ReceiveTurn turn = ring_receiver_->receive(ring, stop, counters, heartbeat);
  if (turn == ReceiveTurn::kEnded) {
    ring_receiver_->finish(counters);
    done.store(true, std::memory_order_release);
  }
  return turn;
}

void PacketSource::run_simulator(const std::atomic<bool>& stop) {
  simulator_->run(stop);
}

}  // namespace pandarcap
