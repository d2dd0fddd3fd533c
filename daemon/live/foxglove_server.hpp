// The live view's server: Foxglove's WebSocket protocol (foxglove.websocket.v1) over websocketpp
// and standalone asio, on a thread of its own (pc-live), read-only.
//
// Channels: the frames as sensor_msgs/msg/PointCloud2 (cdr, ros2msg schema; the MCAP's bytes),
// the health record every second (json) and the sensor's status from it (json: the record's
// "sensor_status"). It never holds up the capture:
//   - frames and health come from the writer through LiveHandover (newest kept, no waiting);
//   - each client has a bounded send queue (client_queue_bytes, about two frames): a message that
//     would overfill it is dropped for that client and counted (messages_dropped), so a stalled
//     viewer costs the others nothing and the writer never knows;
//   - its memory is bounded: max_clients connections (more are refused with HTTP 503), client
//     messages of at most kMaxClientMessageBytes, the handshake's by websocketpp's HTTP parser,
//     handshakes that do not finish within 5 s closed.
// The thread wakes every 10 ms to take what the writer handed over; websocketpp and asio
// allocate on this thread only. Its translation unit is C++17: websocketpp 0.8.2 (Debian 12) does
// not compile as C++20.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "daemon/live/live_handover.hpp"

namespace pandarcap::live {

struct LiveOptions {
  std::string address = "127.0.0.1";
  std::uint16_t port = 8765;  // 0: any free port (tests)
  std::uint32_t max_clients = 4;
  std::string name;  // serverInfo's, "pandarcap VERSION (SENSOR)"
  std::string points_topic = "/pandar/points";
  std::string health_topic = "/pandar/health";
  std::string status_topic = "/pandar/sensor_status";
  std::string points_schema_name;  // "sensor_msgs/msg/PointCloud2"
  std::string points_schema;       // its ros2msg text
  std::string health_schema;       // the health record's JSON schema
  std::size_t client_queue_bytes = 16u << 20;
  // How often a port that could not be bound is tried again (kListenRetrySeconds; a test hook
  // shortens it).
  std::uint32_t listen_retry_ms = kListenRetrySeconds * 1000;
};

class FoxgloveServer {
 public:
  // Binds and listens now. A port that cannot be bound (in use: another program's) is not an
  // error: it is logged, handover.counters.listening stays false (the health names the port),
  // and run() tries again every kListenRetrySeconds until it can. Throws std::runtime_error only
  // for an address that is not an IPv4 address.
  FoxgloveServer(const LiveOptions& options, LiveHandover& handover);
  ~FoxgloveServer();
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  std::uint16_t port() const noexcept;  // the port listened on; 0 while not listening
  // The server thread's body: serves until stop().
  void run();
  // From any thread: run() returns soon after.
  void stop() noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pandarcap::live
