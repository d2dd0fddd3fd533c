#include "daemon/ptc/ptc_client.hpp"

#include <fcntl.h>
#include <fmt/format.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "core/ipv4.hpp"

namespace pandarcap {
namespace {

using Clock = std::chrono::steady_clock;

// Milliseconds left until `deadline` for poll(), at least 0 and at most `cap_ms`.
int remaining_ms(Clock::time_point deadline, long long cap_ms) {
  const auto left =
      std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
  return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left, cap_ms));
}

// The longest a cancellable wait sleeps before looking at `cancel` again. A signal's EINTR
// usually brings it back at once, but one that lands between the look and the poll (or on
// another thread, or deferred by a sanitizer's signal handling) would not: without a cap, SIGTERM
// during the start could wait out a whole PTC deadline.
constexpr long long kCancelCheckMs = 100;

// Waits for `events` on `fd` until `deadline`: true when ready, false at the deadline or when
// `cancel` is raised (seen within kCancelCheckMs).
bool wait_for(int fd, short events, Clock::time_point deadline, const std::atomic<bool>* cancel) {
  for (;;) {
    if (cancel != nullptr && cancel->load(std::memory_order_relaxed)) return false;
    pollfd p{fd, events, 0};
    const int n =
        ::poll(&p, 1, remaining_ms(deadline, cancel != nullptr ? kCancelCheckMs : 60'000));
    if (n > 0) return true;
    if (n == 0) {
      if (Clock::now() >= deadline) return false;
      continue;
    }
    if (errno != EINTR) return true;  // the read or write that follows reports it
  }
}

}  // namespace

PtcClient::PtcClient(PtcClientOptions options)
    : options_(std::move(options)),
      endpoint_(fmt::format("{}:{}", options_.address, options_.port)) {
  require_ipv4(options_.address, "sensor_ip");
}

PtcError PtcClient::fail(ptc::Command command, ptc::ErrorKind kind, std::string_view what,
                         std::uint8_t return_code) {
  fd_.reset();  // whatever is left in the stream belongs to no request of ours
  ++errors_total_;
  ++errors_[static_cast<std::size_t>(kind)];
  return PtcError{kind, return_code,
                  fmt::format("PTC {} {}: {}", endpoint_, ptc::to_string(command), what)};
}

std::optional<PtcError> PtcClient::connect(ptc::Command command) {
  const sockaddr_in to = ipv4_endpoint(options_.address, options_.port, "sensor_ip");
  io::UniqueFd fd(::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
  if (!fd) return fail(command, ptc::ErrorKind::kConnectFailed, std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd.get(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  const auto deadline = Clock::now() + options_.timeout;
  if (::connect(fd.get(), reinterpret_cast<const sockaddr*>(&to), sizeof to) != 0) {
    if (errno != EINPROGRESS) {
      return fail(command, ptc::ErrorKind::kConnectFailed,
                  fmt::format("cannot connect: {}", std::strerror(errno)));
    }
    if (!wait_for(fd.get(), POLLOUT, deadline, options_.cancel)) {
      return fail(command, ptc::ErrorKind::kTimeout,
                  fmt::format("no connection within {} ms (sensor off, or another address?)",
                              options_.timeout.count()));
    }
    int so_error = 0;
    socklen_t size = sizeof so_error;
    ::getsockopt(fd.get(), SOL_SOCKET, SO_ERROR, &so_error, &size);
    if (so_error != 0) {
      return fail(command, ptc::ErrorKind::kConnectFailed,
                  fmt::format("cannot connect: {}", std::strerror(so_error)));
    }
  }
  fd_ = std::move(fd);
  return std::nullopt;
}

PtcReply PtcClient::request(ptc::Command command, std::span<const std::uint8_t> payload,
                            bool unsupported_is_an_answer) {
  ++requests_;
  PtcReply reply;
  if (!fd_) {
    if (auto problem = connect(command)) {
      reply.error = std::move(problem);
      return reply;
    }
  }
  const auto deadline = Clock::now() + options_.timeout;
  const auto timed_out = [&](std::string_view stage, std::size_t got, std::size_t wanted) {
    return fail(command, ptc::ErrorKind::kTimeout,
                fmt::format("timed out after {} ms {} ({} of {} bytes)", options_.timeout.count(),
                            stage, got, wanted));
  };

  // The request: header and payload in one buffer, sent whole (a few bytes: one segment).
  std::vector<std::uint8_t> out(ptc::kHeaderBytes + payload.size());
  const auto header = ptc::request_header(command, static_cast<std::uint32_t>(payload.size()));
  std::copy(header.begin(), header.end(), out.begin());
  std::copy(payload.begin(), payload.end(), out.begin() + ptc::kHeaderBytes);
  for (std::size_t sent = 0; sent < out.size();) {
    const ssize_t n = ::send(fd_.get(), out.data() + sent, out.size() - sent, MSG_NOSIGNAL);
    if (n > 0) {
      sent += static_cast<std::size_t>(n);
    } else if (n < 0 && (errno == EAGAIN || errno == EINTR)) {
      if (!wait_for(fd_.get(), POLLOUT, deadline, options_.cancel)) {
        reply.error = timed_out("sending the request", sent, out.size());
        return reply;
      }
    } else {
      reply.error = fail(command, ptc::ErrorKind::kIncomplete,
                         fmt::format("cannot send the request: {}", std::strerror(errno)));
      return reply;
    }
  }

  // Reads exactly `size` bytes into `into` before the deadline; an error when it cannot.
  const auto read_exactly = [&](std::uint8_t* into, std::size_t size,
                                std::string_view stage) -> std::optional<PtcError> {
    for (std::size_t got = 0; got < size;) {
      const ssize_t n = ::recv(fd_.get(), into + got, size - got, 0);
      if (n > 0) {
        got += static_cast<std::size_t>(n);
      } else if (n == 0) {
        return fail(
            command, ptc::ErrorKind::kIncomplete,
            fmt::format("the sensor closed the connection {} ({} of {} bytes)", stage, got, size));
      } else if (errno == EAGAIN || errno == EINTR) {
        if (!wait_for(fd_.get(), POLLIN, deadline, options_.cancel))
          return timed_out(stage, got, size);
      } else {
        return fail(command, ptc::ErrorKind::kIncomplete,
                    fmt::format("connection failed {}: {}", stage, std::strerror(errno)));
      }
    }
    return std::nullopt;
  };

  std::array<std::uint8_t, ptc::kHeaderBytes> head{};
  if (auto problem = read_exactly(head.data(), head.size(), "reading the response header")) {
    reply.error = std::move(problem);
    return reply;
  }
  const ptc::ResponseHeader h = ptc::decode_header(head);
  if (auto problem = ptc::check_response_header(h, head, command, options_.max_payload_bytes)) {
    reply.error = fail(command, problem->kind, problem->message);
    return reply;
  }
  reply.payload.resize(h.payload_length);  // bounded by max_payload_bytes, checked above
  if (auto problem = read_exactly(reply.payload.data(), reply.payload.size(),
                                  "reading the response payload")) {
    reply.payload.clear();
    reply.error = std::move(problem);
    return reply;
  }
  if (h.return_code == ptc::kReturnUnsupported && unsupported_is_an_answer) {
    reply.payload.clear();
    reply.error = PtcError{
        ptc::ErrorKind::kErrorCode, h.return_code,
        fmt::format("PTC {} {}: not supported by this sensor", endpoint_, ptc::to_string(command))};
    return reply;
  }
  if (h.return_code != ptc::kReturnOk) {
    // The stream is in step (the whole response was read): the connection could be kept, but
    // a sensor that errs is asked again from scratch, as nebula does.
    reply.payload.clear();
    reply.error = fail(command, ptc::ErrorKind::kErrorCode,
                       fmt::format("the sensor answered return code 0x{:02X} ({})", h.return_code,
                                   ptc::describe_return_code(h.return_code)),
                       h.return_code);
  }
  return reply;
}

}  // namespace pandarcap
