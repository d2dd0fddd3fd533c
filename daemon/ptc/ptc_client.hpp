// A client of the sensor's TCP control protocol (PTC, port 9347): one request at a time, each
// bounded in time and memory, every failure a message and a counter, never a hang.
//
//   PtcClient client({.address = "192.168.1.201"});
//   PtcReply reply = client.request(ptc::Command::kGetStatus);
//   if (!reply.ok()) log(reply.error.message);   // "192.168.1.201:9347: status: timed out ..."
//
// Deadlines: connecting gets `timeout`; then the request and its whole response (header and
// payload together) get `timeout` more. A sensor that sends a byte a second is given up at the
// deadline, not kept on for as long as it trickles. The payload's announced length is checked
// against `max_payload_bytes` before anything is allocated for it.
//
// The connection is kept for the next request (nebula does the same) and dropped after any
// failure, so a desynchronised stream is never read further; the next request reconnects.
// Not thread-safe: one owner (the start-up, the status poller, pandarcap-ctl).
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/ptc/ptc_protocol.hpp"
#include "daemon/io/unique_fd.hpp"

namespace pandarcap {

struct PtcClientOptions {
  std::string address;  // the sensor's IPv4 address
  std::uint16_t port = ptc::kDefaultPort;
  std::chrono::milliseconds timeout{2000};      // to connect, and then for the whole response
  std::uint32_t max_payload_bytes = 64 * 1024;  // a calibration table is ~1.5 kB
  // When set and raised (by a signal handler, which also interrupts the wait), a request in
  // progress gives up at once, as at its deadline.
  const std::atomic<bool>* cancel = nullptr;
};

struct PtcError {
  ptc::ErrorKind kind = ptc::ErrorKind::kConnectFailed;
  std::uint8_t return_code = 0;  // kErrorCode: the sensor's
  std::string message;           // whole sentence, endpoint and command first
};

struct PtcReply {
  std::vector<std::uint8_t> payload;
  std::optional<PtcError> error;
  bool ok() const noexcept { return !error; }
};

class PtcClient {
 public:
  // Throws std::invalid_argument when `address` is not an IPv4 address.
  explicit PtcClient(PtcClientOptions options);

  // Sends `command` with `payload` and waits for its response, within the deadlines. With
  // `unsupported_is_an_answer`, a return code 0x05 (unsupported command) is still reported as
  // an error of kind kErrorCode but not counted in errors(): asking whether a sensor has a
  // feature is not a failure when it says no.
  PtcReply request(ptc::Command command, std::span<const std::uint8_t> payload = {},
                   bool unsupported_is_an_answer = false);

  // A failure of `command`: counted in errors(), the connection dropped (whatever is left in
  // the stream belongs to no request), and the message built. Used by request() and by callers
  // that find the payload does not parse.
  PtcError fail(ptc::Command command, ptc::ErrorKind kind, std::string_view what,
                std::uint8_t return_code = 0);

  std::uint64_t requests() const noexcept { return requests_; }
  std::uint64_t errors() const noexcept { return errors_total_; }
  std::uint64_t errors(ptc::ErrorKind kind) const noexcept {
    return errors_[static_cast<std::size_t>(kind)];
  }
  const std::string& endpoint() const noexcept { return endpoint_; }  // "192.168.1.201:9347"
  const PtcClientOptions& options() const noexcept { return options_; }

 private:
  std::optional<PtcError> connect(ptc::Command command);

  PtcClientOptions options_;
  std::string endpoint_;
  io::UniqueFd fd_;
  std::uint64_t requests_ = 0;
  std::uint64_t errors_total_ = 0;
  std::array<std::uint64_t, ptc::kErrorKindCount> errors_{};
};

}  // namespace pandarcap
