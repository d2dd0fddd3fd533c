// A PTC server that misbehaves on purpose (spec §6), on 127.0.0.1 and a free port: the client,
// the daemon and pandarcap-ctl must each fail boundedly and clearly against every behaviour.
// It serves one connection at a time and answers each request as `behaviour` says; a stop event
// ends it whatever it is doing (a trickle, a silence), so the destructor never waits.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "daemon/io/unique_fd.hpp"

namespace pandarcap::test {

enum class Hostile {
  kSilent,            // accepts, reads the request, never answers
  kCloseAtOnce,       // accepts and closes before any byte
  kWrongMagic,        // "HTTP/1.1 400" instead of a PTC header
  kWrongCommand,      // echoes another command byte
  kErrorCode,         // return code 0x03 (invalid data), no payload
  kErrorCodePayload,  // return code 0x07 with a 5-byte message
  kEmptyPayload,      // success, payload length 0
  kHugeLength,        // success announcing 2^32-1 payload bytes, then silence
  kCutPayload,        // success announcing 100 bytes, sends 10, closes
  kCutHeader,         // 5 bytes of a header, closes
  kTrickle,           // a correct status answer, one byte every `trickle_ms`
  kShortStatus,       // a status payload of 40 bytes
  kLongStatus,        // a status payload of 60 bytes (54 + 6 newer-firmware bytes)
  kBadCalibration,    // a calibration answer with 39 channels
  kGarbageStatus,     // a well-formed status of impossible values; other commands: unsupported
  kFlapping,          // status answers in turn: right, garbage, none (the connection closed)
};

class HostilePtcServer {
 public:
  explicit HostilePtcServer(Hostile behaviour, int trickle_ms = 1000);
  ~HostilePtcServer();
  HostilePtcServer(const HostilePtcServer&) = delete;
  HostilePtcServer& operator=(const HostilePtcServer&) = delete;

  std::uint16_t port() const noexcept { return port_; }
  std::uint64_t connections() const noexcept { return connections_.load(); }

 private:
  void serve();
  void answer(int fd);
  bool send_all(int fd, const std::vector<std::uint8_t>& bytes);
  bool wait_stop(int ms);  // true when stopped during the wait

  Hostile behaviour_;
  int trickle_ms_;
  std::uint16_t port_ = 0;  // before listen_fd_: set while it is initialised
  io::UniqueFd listen_fd_, stop_fd_;
  std::atomic<std::uint64_t> connections_{0};
  std::uint64_t status_answers_ = 0;  // the serving thread's own
  std::thread thread_;
};

// A TCP port on 127.0.0.1 that refuses connections (bound, never listening: nobody else can
// take it while the returned descriptor is open).
struct RefusingPort {
  RefusingPort();
  std::uint16_t port = 0;  // before fd: set while it is initialised
  io::UniqueFd fd;
};

}  // namespace pandarcap::test
