// Where the daemon's packets come from, opened before READY: the live socket, the socket the
// built-in simulated sensor sends to, or a capture file replayed.
//
// Opening is where a source fails (a port in use, a missing file): before any thread starts, so
// the start can report it with an exit status. run() is the source thread's body.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "config/daemon_config.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/replay_source.hpp"
#include "daemon/simulated_sender.hpp"
#include "daemon/udp_receiver.hpp"

namespace pandarcap {

class PacketSource {
 public:
  // Binds the socket (and, simulated, the simulator's), or opens the capture file. Throws
  // CaptureError for a capture that cannot be read, std::exception for the rest.
  PacketSource(const DaemonConfig& config, const RunSource& source);

  const char* thread_name() const noexcept { return replay_ ? "pc-replay" : "pc-receive"; }
  bool simulated() const noexcept { return simulator_ != nullptr; }

  // The source thread: receives (or replays) into the ring until `pipe.stop_source`, or the end
  // of the file; then sets `pipe.source_done`.
  void run(Pipeline& pipe);
  // The simulator thread (simulated() only): sends until `stop`.
  void run_simulator(const std::atomic<bool>& stop);

  // After run(): how the replay ended (replays only).
  bool replayed() const noexcept { return replay_ != nullptr; }
  const ReplayResult& replay_result() const noexcept { return replay_result_; }

 private:
  std::unique_ptr<UdpReceiver> receiver_;
  std::unique_ptr<ReplaySource> replay_;
  std::unique_ptr<SimulatedSender> simulator_;
  ReplayResult replay_result_;
};

}  // namespace pandarcap
