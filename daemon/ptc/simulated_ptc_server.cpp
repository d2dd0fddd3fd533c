#include "daemon/ptc/simulated_ptc_server.hpp"

#include <netinet/in.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>

#include <array>
#include <cerrno>

#include "core/ipv4.hpp"
#include "core/ptc/ptc_protocol.hpp"
#include "daemon/io/errors.hpp"

namespace pandarcap {
namespace {

constexpr std::uint32_t kMaxRequestPayload = 64;

}  // namespace

SimulatedPtcServer::SimulatedPtcServer(SimulatedUnit unit, const std::string& address,
                                       std::uint16_t port)
    : unit_(std::move(unit)),
      calibration_csv_(unit_.calibration.to_csv()),
      powered_on_(std::chrono::steady_clock::now()),
      ptp_state_(unit_.ptp_state) {
  const sockaddr_in at = ipv4_endpoint(address, port, "simulated sensor PTC address");
  listen_fd_.reset(::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
  if (!listen_fd_) io::throw_errno("simulated sensor PTC socket");
  const int one = 1;
  ::setsockopt(listen_fd_.get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (::bind(listen_fd_.get(), reinterpret_cast<const sockaddr*>(&at), sizeof at) != 0 ||
      ::listen(listen_fd_.get(), 4) != 0) {
    io::throw_errno("simulated sensor cannot listen for PTC on " + address);
  }
  sockaddr_in bound{};
  socklen_t size = sizeof bound;
  ::getsockname(listen_fd_.get(), reinterpret_cast<sockaddr*>(&bound), &size);
  port_ = ntohs(bound.sin_port);
  stop_fd_.reset(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
  if (!stop_fd_) io::throw_errno("simulated sensor PTC eventfd");
  thread_ = std::thread([this] { serve(); });
}

SimulatedPtcServer::~SimulatedPtcServer() {
  const std::uint64_t one = 1;
  [[maybe_unused]] const ssize_t n = ::write(stop_fd_.get(), &one, sizeof one);
  if (thread_.joinable()) thread_.join();
}

void SimulatedPtcServer::serve() {
  for (;;) {
    std::array<pollfd, 2> fds{pollfd{listen_fd_.get(), POLLIN, 0},
                              pollfd{stop_fd_.get(), POLLIN, 0}};
    if (::poll(fds.data(), fds.size(), -1) < 0 && errno != EINTR) return;
    if (fds[1].revents != 0) return;
    if (fds[0].revents == 0) continue;
    io::UniqueFd connection(::accept4(listen_fd_.get(), nullptr, nullptr, SOCK_CLOEXEC));
    if (connection) serve_connection(connection.get());
  }
}

void SimulatedPtcServer::serve_connection(int fd) {
  // Blocking reads and writes on the connection, each preceded by a poll that the stop event
  // also ends, so the destructor never waits on a client.
  const auto wait_readable = [&] {
    std::array<pollfd, 2> fds{pollfd{fd, POLLIN, 0}, pollfd{stop_fd_.get(), POLLIN, 0}};
    while (::poll(fds.data(), fds.size(), -1) < 0) {
      if (errno != EINTR) return false;
    }
    return fds[1].revents == 0;
  };
  const auto read_exactly = [&](std::uint8_t* into, std::size_t size) {
    for (std::size_t got = 0; got < size;) {
      if (!wait_readable()) return false;
      const ssize_t n = ::recv(fd, into + got, size - got, 0);
      if (n <= 0) return false;
      got += static_cast<std::size_t>(n);
    }
    return true;
  };
  for (;;) {
    std::array<std::uint8_t, ptc::kHeaderBytes> head{};
    if (!read_exactly(head.data(), head.size())) return;
    const ptc::ResponseHeader request = ptc::decode_header(head);
    if (head[0] != ptc::kMagic[0] || head[1] != ptc::kMagic[1] ||
        request.payload_length > kMaxRequestPayload) {
      return;
    }
    std::array<std::uint8_t, kMaxRequestPayload> payload{};
    if (!read_exactly(payload.data(), request.payload_length)) return;
    requests_.fetch_add(1, std::memory_order_relaxed);
    std::uint8_t return_code = ptc::kReturnOk;
    const std::vector<std::uint8_t> body =
        answer(request.command, std::span(payload).first(request.payload_length), return_code);
    std::vector<std::uint8_t> out(ptc::kHeaderBytes + body.size());
    const auto header = ptc::encode_header(static_cast<ptc::Command>(request.command), return_code,
                                           static_cast<std::uint32_t>(body.size()));
    std::copy(header.begin(), header.end(), out.begin());
    std::copy(body.begin(), body.end(), out.begin() + ptc::kHeaderBytes);
    for (std::size_t sent = 0; sent < out.size();) {
      const ssize_t n = ::send(fd, out.data() + sent, out.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return;
      sent += static_cast<std::size_t>(n);
    }
  }
}

std::vector<std::uint8_t> SimulatedPtcServer::answer(std::uint8_t command,
                                                     std::span<const std::uint8_t> payload,
                                                     std::uint8_t& return_code) const {
  switch (static_cast<ptc::Command>(command)) {
    case ptc::Command::kGetCalibration:
      return {calibration_csv_.begin(), calibration_csv_.end()};
    case ptc::Command::kGetInventory:
      return ptc::encode_inventory(unit_.inventory);
    case ptc::Command::kGetConfig:
      return ptc::encode_settings(unit_.settings);
    case ptc::Command::kGetStatus: {
      const auto uptime = std::chrono::duration_cast<std::chrono::seconds>(
          std::chrono::steady_clock::now() - powered_on_);
      ptc::SensorStatus status = unit_.status(static_cast<std::uint32_t>(uptime.count()));
      status.ptp_state = ptp_state_.load();
      return ptc::encode_status(status);
    }
    case ptc::Command::kPtpDiagnostics:
      if (unit_.answers_ptp_diagnostics && payload.size() == 1 &&
          payload[0] == ptc::kPtpQueryStatus) {
        return ptc::encode_ptp_status(ptc::PtpDiagnostics{
            unit_.ptp_offset_ns, static_cast<std::int32_t>(ptp_state_.load()), 1000});
      }
      break;
  }
  return_code = ptc::kReturnUnsupported;
  return {};
}

}  // namespace pandarcap
