#include "daemon/source/simulated_sender.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <system_error>

#include "core/ipv4.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sim/simulated_unit.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"

namespace pandarcap {
namespace {

constexpr std::size_t kMaxBurst = 64;

}  // namespace

SimulatedSender::SimulatedSender(SensorModelId model, const SyntheticSensorConfig& config,
                                 const std::string& source_ip, const std::string& destination_ip,
                                 std::uint16_t destination_port)
    // Rendered with the simulated unit's own table, the one its PTC serves.
    : sensor_(model, model_sensor_config(config), simulated_unit_calibration(model)) {
  const sockaddr_in source = ipv4_endpoint(source_ip, 0, "simulator source");
  const sockaddr_in destination =
      ipv4_endpoint(destination_ip, destination_port, "simulator destination");
  fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd_ < 0) io::throw_errno("simulator socket");
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&source), sizeof source) != 0 ||
      ::connect(fd_, reinterpret_cast<const sockaddr*>(&destination), sizeof destination) != 0) {
    const int error = errno;
    ::close(fd_);
    io::throw_error(error, "simulator cannot send from " + source_ip + " to " + destination_ip);
  }
}

SimulatedSender::~SimulatedSender() {
  if (fd_ >= 0) ::close(fd_);
}

void SimulatedSender::run(const std::atomic<bool>& stop) {
  std::array<std::array<std::uint8_t, kLargestDatagramBytes>, kMaxBurst> packets{};
  std::array<iovec, kMaxBurst> iov{};
  std::array<mmsghdr, kMaxBurst> messages{};
  const std::int64_t period = sensor_.packet_period_ns();
  const std::int64_t start = monotonic_ns();
  std::uint64_t produced = 0;
  while (!stop.load(std::memory_order_relaxed)) {
    // Every packet whose time has come, in bursts of at most kMaxBurst.
    const std::int64_t now = monotonic_ns();
    const auto due = static_cast<std::uint64_t>((now - start) / period + 1);
    std::size_t n = 0;
    while (produced < due && n < kMaxBurst) {
      const std::size_t size = sensor_.next(packets[n]);
      iov[n] = {packets[n].data(), size};
      messages[n] = {};
      messages[n].msg_hdr.msg_iov = &iov[n];
      messages[n].msg_hdr.msg_iovlen = 1;
      ++n;
      ++produced;
    }
    std::size_t done = 0;
    while (done < n) {
      const int sent = ::sendmmsg(fd_, messages.data() + done, static_cast<unsigned>(n - done), 0);
      if (sent <= 0) {
        // Loopback with nobody reading yet (ECONNREFUSED) or a full buffer: the packet is lost,
        // like a real sensor's would be.
        errors_.fetch_add(1, std::memory_order_relaxed);
        ++done;
        continue;
      }
      done += static_cast<std::size_t>(sent);
      sent_.fetch_add(static_cast<std::uint64_t>(sent), std::memory_order_relaxed);
    }
    if (produced >= due) {
      const std::int64_t next = start + static_cast<std::int64_t>(produced) * period;
      const std::int64_t wake = std::max(next, now + 1'000'000);  // at most ~1000 wake-ups/s
      const timespec ts{static_cast<time_t>(wake / 1'000'000'000),
                        static_cast<long>(wake % 1'000'000'000)};
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    }
  }
}

}  // namespace pandarcap
