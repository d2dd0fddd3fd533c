#include "support/hostile_ptc_server.hpp"

#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>

#include <array>
#include <cerrno>
#include <stdexcept>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/ptc_protocol.hpp"
#include "core/sim/simulated_unit.hpp"

namespace pandarcap::test {
namespace {

io::UniqueFd bound_socket(std::uint16_t& port) {
  io::UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
  sockaddr_in at{};
  at.sin_family = AF_INET;
  at.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (!fd || ::bind(fd.get(), reinterpret_cast<const sockaddr*>(&at), sizeof at) != 0) {
    throw std::runtime_error("test PTC server: cannot bind 127.0.0.1");
  }
  socklen_t size = sizeof at;
  ::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&at), &size);
  port = ntohs(at.sin_port);
  return fd;
}

std::vector<std::uint8_t> response(ptc::Command command, std::uint8_t code,
                                   const std::vector<std::uint8_t>& payload) {
  const auto h = ptc::encode_header(command, code, static_cast<std::uint32_t>(payload.size()));
  std::vector<std::uint8_t> out(ptc::kHeaderBytes + payload.size());
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = i < ptc::kHeaderBytes ? h[i] : payload[i - ptc::kHeaderBytes];
  return out;
}

}  // namespace

RefusingPort::RefusingPort() : fd(bound_socket(port)) {}

HostilePtcServer::HostilePtcServer(Hostile behaviour, int trickle_ms)
    : behaviour_(behaviour), trickle_ms_(trickle_ms), listen_fd_(bound_socket(port_)) {
  if (::listen(listen_fd_.get(), 4) != 0) throw std::runtime_error("test PTC server: listen");
  stop_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
  thread_ = std::thread([this] { serve(); });
}

HostilePtcServer::~HostilePtcServer() {
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t n = ::write(stop_fd_.get(), &one, sizeof one);
  thread_.join();
}

bool HostilePtcServer::wait_stop(int ms) {
  pollfd p{stop_fd_.get(), POLLIN, 0};
  return ::poll(&p, 1, ms) > 0;
}

bool HostilePtcServer::send_all(int fd, const std::vector<std::uint8_t>& bytes) {
  for (std::size_t sent = 0; sent < bytes.size();) {
    const ssize_t n = ::send(fd, bytes.data() + sent, bytes.size() - sent, MSG_NOSIGNAL);
    if (n <= 0) return false;
    sent += static_cast<std::size_t>(n);
  }
  return true;
}

void HostilePtcServer::serve() {
  for (;;) {
    std::array<pollfd, 2> fds{pollfd{listen_fd_.get(), POLLIN, 0},
                              pollfd{stop_fd_.get(), POLLIN, 0}};
    if (::poll(fds.data(), fds.size(), -1) < 0 && errno != EINTR) return;
    if (fds[1].revents != 0) return;
    if (fds[0].revents == 0) continue;
    io::UniqueFd connection(::accept4(listen_fd_.get(), nullptr, nullptr, SOCK_CLOEXEC));
    if (!connection) continue;
    connections_.fetch_add(1);
    answer(connection.get());
  }
}

void HostilePtcServer::answer(int fd) {
  if (behaviour_ == Hostile::kCloseAtOnce) return;
  // Requests, one after another, until the client goes away or the server stops.
  for (;;) {
    std::array<std::uint8_t, ptc::kHeaderBytes> head{};
    for (std::size_t got = 0; got < head.size();) {
      std::array<pollfd, 2> fds{pollfd{fd, POLLIN, 0}, pollfd{stop_fd_.get(), POLLIN, 0}};
      ::poll(fds.data(), fds.size(), -1);
      if (fds[1].revents != 0) return;
      const ssize_t n = ::recv(fd, head.data() + got, head.size() - got, 0);
      if (n <= 0) return;
      got += static_cast<std::size_t>(n);
    }
    const auto command = static_cast<ptc::Command>(head[2]);
    const ptc::SensorStatus status = simulated_unit().status(100);
    std::vector<std::uint8_t> status_bytes = ptc::encode_status(status);
    switch (behaviour_) {
      case Hostile::kSilent:
        continue;  // reads the next request, if any; answers none
      case Hostile::kCloseAtOnce:
        return;
      case Hostile::kWrongMagic: {
        const std::string http = "HTTP/1.1 400 Bad Request\r\n\r\n";
        send_all(fd, std::vector<std::uint8_t>(http.begin(), http.end()));
        return;
      }
      case Hostile::kWrongCommand:
        send_all(fd, response(ptc::Command::kGetInventory, 0, status_bytes));
        break;
      case Hostile::kErrorCode:
        send_all(fd, response(command, 0x03, {}));
        break;
      case Hostile::kErrorCodePayload:
        send_all(fd, response(command, 0x07, {'o', 'o', 'p', 's', '!'}));
        break;
      case Hostile::kEmptyPayload:
        send_all(fd, response(command, 0, {}));
        break;
      case Hostile::kHugeLength: {
        const auto h = ptc::encode_header(command, 0, 0xFFFFFFFFu);
        send_all(fd, std::vector<std::uint8_t>(h.begin(), h.end()));
        continue;  // then silence: reads on until the client gives up
      }
      case Hostile::kCutPayload: {
        std::vector<std::uint8_t> bytes = response(command, 0, std::vector<std::uint8_t>(100, 7));
        bytes.resize(ptc::kHeaderBytes + 10);
        send_all(fd, bytes);
        return;
      }
      case Hostile::kCutHeader: {
        std::vector<std::uint8_t> bytes = response(command, 0, status_bytes);
        bytes.resize(5);
        send_all(fd, bytes);
        return;
      }
      case Hostile::kTrickle: {
        for (const std::uint8_t byte : response(command, 0, status_bytes)) {
          if (!send_all(fd, {byte}) || wait_stop(trickle_ms_)) return;
        }
        break;
      }
      case Hostile::kShortStatus:
        status_bytes.resize(40);
        send_all(fd, response(command, 0, status_bytes));
        break;
      case Hostile::kLongStatus:
        status_bytes.resize(60, 0xAB);
        send_all(fd, response(command, 0, status_bytes));
        break;
      case Hostile::kGarbageStatus:
      case Hostile::kFlapping: {
        if (command != ptc::Command::kGetStatus) {
          send_all(fd, response(command, 0x05, {}));  // unsupported: the daemon goes without
          break;
        }
        const std::uint64_t turn = status_answers_++;
        if (behaviour_ == Hostile::kFlapping && turn % 3 == 0) {
          send_all(fd, response(command, 0, status_bytes));
          break;
        }
        if (behaviour_ == Hostile::kFlapping && turn % 3 == 2) return;  // closes: no answer
        // What a corrupt answer of the right length can say: 53 029 RPM, ±17 million °C, an
        // uptime of 117 years, a PTP state that does not exist.
        ptc::SensorStatus garbage = status;
        garbage.motor_rpm = 53029;
        garbage.uptime_s = 117u * 365 * 24 * 3600;
        garbage.temperature_centi_c[0] = 1'717'171'717;
        garbage.temperature_centi_c[3] = -1'717'171'717;
        garbage.gps_pps_locked = 7;
        garbage.ptp_state = 9;
        send_all(fd, response(command, 0, ptc::encode_status(garbage)));
        break;
      }
      case Hostile::kBadCalibration: {
        std::string csv = Calibration::nominal().to_csv();
        csv.resize(csv.rfind('\n', csv.size() - 2) + 1);  // the last channel's row cut off
        send_all(fd, response(command, 0, std::vector<std::uint8_t>(csv.begin(), csv.end())));
        break;
      }
    }
  }
}

}  // namespace pandarcap::test
