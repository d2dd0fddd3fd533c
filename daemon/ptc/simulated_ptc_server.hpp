// The simulated Pandar40P's control port: answers PTC requests (calibration, inventory, config,
// status) for a SimulatedUnit, from a thread of its own, on 127.0.0.1 and a free port unless one
// is given. `pandarcapd --simulate` starts one so the daemon fetches the unit's calibration as it
// would from a real sensor; the tests and pandarcap-ctl's tests talk to it too.
//
// Like the sensor it serves one connection at a time, any number of requests on it, in order.
// 0x06 (PTP diagnostics) is answered only by a unit that says so (query 0x01); it and every
// command that would change a sensor are otherwise answered with return code 0x05 (unsupported). A
// request announcing more than 64 payload bytes ends the connection.
#pragma once

#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <thread>

#include "core/sim/simulated_unit.hpp"
#include "daemon/io/unique_fd.hpp"

namespace pandarcap {

class SimulatedPtcServer {
 public:
  // Listening once constructed; throws std::system_error when the address cannot be bound.
  explicit SimulatedPtcServer(SimulatedUnit unit, const std::string& address = "127.0.0.1",
                              std::uint16_t port = 0);
  ~SimulatedPtcServer();  // stops the thread, closes the sockets
  SimulatedPtcServer(const SimulatedPtcServer&) = delete;
  SimulatedPtcServer& operator=(const SimulatedPtcServer&) = delete;

  std::uint16_t port() const noexcept { return port_; }
  std::uint64_t requests() const noexcept { return requests_.load(std::memory_order_relaxed); }
  // What the status answers from now on (tests: a clock that loses its lock).
  void set_ptp_state(std::uint8_t state) noexcept { ptp_state_.store(state); }

 private:
  void serve();
  void serve_connection(int fd);
  std::vector<std::uint8_t> answer(std::uint8_t command, std::span<const std::uint8_t> payload,
                                   std::uint8_t& return_code) const;

  SimulatedUnit unit_;
  std::string calibration_csv_;
  io::UniqueFd listen_fd_, stop_fd_;
  std::uint16_t port_ = 0;
  std::chrono::steady_clock::time_point powered_on_;
  std::atomic<std::uint64_t> requests_{0};
  std::atomic<std::uint8_t> ptp_state_;
  std::thread thread_;
};

}  // namespace pandarcap
