#include "daemon/packet_source.hpp"

#include <spdlog/spdlog.h>

#include "daemon/clocks.hpp"

namespace pandarcap {

PacketSource::PacketSource(const DaemonConfig& config, const RunSource& source) {
  if (source.kind == RunSource::Kind::kReplay) {
    replay_ = std::make_unique<ReplaySource>(replay_options(config, source));
    return;
  }
  receiver_ = std::make_unique<UdpReceiver>(receiver_options(config, source));
  if (source.kind == RunSource::Kind::kSimulated) {
    const SyntheticSensorConfig sc = simulated_sensor_config(source, realtime_ns());
    simulator_ =
        std::make_unique<SimulatedSender>(sc, "127.0.0.1", "127.0.0.1", receiver_->bound_port());
    spdlog::info("simulated sensor: {} RPM, {} return{}, sending to 127.0.0.1:{}", sc.rpm,
                 to_string(sc.return_mode), sc.udp_sequence ? ", UDP sequence" : "",
                 receiver_->bound_port());
  }
}

void PacketSource::run(Pipeline& pipe) {
  if (replay_) {
    replay_result_ =
        replay_->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive);
  } else {
    receiver_->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive);
  }
  // release: everything the source published happens before the decoder sees "done".
  pipe.source_done.store(true, std::memory_order_release);
}

void PacketSource::run_simulator(const std::atomic<bool>& stop) {
  simulator_->run(stop);
}

}  // namespace pandarcap
