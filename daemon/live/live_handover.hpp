// What the writer thread hands the live view's server thread (daemon/live/foxglove_server.hpp),
// and the counters the server keeps for the health record.
//
//   writer thread ──offer_frame / offer_health (live_publish.hpp)──▶ LiveHandover ──▶ server thread
//
// Two slots, each keeping only the newest message (latest_message.hpp): the frames as whole
// Foxglove binary messages (opcode, subscription id, time, PointCloud2 CDR), and the health
// record's JSON line. All their memory is reserved when the handover is made, at start-up; the
// writer copies a frame in only while a client subscribes to the points, never waits and never
// allocates; the server thread takes what is newest whenever it wakes. Plain C++17 (the server's
// translation unit includes it).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>

#include "daemon/live/latest_message.hpp"

namespace pandarcap::live {

// Foxglove's binary "Message Data" (server → client): opcode 0x01, the subscription id (uint32
// LE, written per client by the server), the log time (uint64 LE ns), then the message's bytes.
inline constexpr std::uint8_t kMessageDataOpcode = 0x01;
inline constexpr std::size_t kSubscriptionIdOffset = 1;
inline constexpr std::size_t kMessageDataHeaderBytes = 1 + 4 + 8;

// The health record's JSON line, at most (a record is a few kB; a longer one is dropped, counted).
inline constexpr std::size_t kHealthMessageCapacity = 256 * 1024;

// Written by the server thread, read by the writer (its health record) and the tests.
struct LiveCounters {
  std::atomic<std::uint64_t> clients{0};             // connected now
  std::atomic<std::uint64_t> points_subscribers{0};  // clients subscribed to the points now
  std::atomic<std::uint64_t> messages_sent{0};       // handed to a client's socket
  // Messages a client did not get: its send queue was full (one per client and message), or the
  // server thread had not taken a frame before the writer replaced it with the next.
  std::atomic<std::uint64_t> messages_dropped{0};
  // Whether the server listens now. A port it cannot bind (another program's: foxglove_bridge's
  // default is 8765 too) leaves the capture running: the server tries again every
  // kListenRetrySeconds, and the health is degraded, naming the port and listen_errno, until then.
  std::atomic<bool> listening{false};
  std::atomic<std::uint16_t> port{0};             // asked for (the bound one once listening)
  std::atomic<int> listen_errno{0};               // the last failure (EADDRINUSE: in use)
  std::atomic<std::uint32_t> listen_retry_ms{0};  // how often it tries again (LiveOptions)
};

inline constexpr int kListenRetrySeconds = 10;

struct LiveHandover {
  // `points_capacity_bytes`: the largest frame's whole binary message (live_publish.hpp).
  explicit LiveHandover(std::size_t points_capacity_bytes)
      : points(points_capacity_bytes), health(kHealthMessageCapacity) {}

  LatestMessage points;  // binary messages, subscription id left 0
  LatestMessage health;  // the JSON line, '\n' removed; its time in the first 8 bytes (LE)
  LiveCounters counters;
};

}  // namespace pandarcap::live
