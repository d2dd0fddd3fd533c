// The receiving end of NOTIFY_SOCKET, as systemd is for a Type=notify service: the tests that
// check what the daemon tells its supervisor (READY, WATCHDOG, STATUS, STOPPING) bind one and
// hand its path to the daemon in its environment.
#pragma once

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "bench/child_process.hpp"

namespace pandarcap::test {

// The receiving end of NOTIFY_SOCKET: every datagram the daemon sent, in order.
class NotifyListener {
 public:
  explicit NotifyListener(const std::filesystem::path& path) {
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    REQUIRE(fd_ >= 0);
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    REQUIRE(path.native().size() < sizeof address.sun_path);
    std::snprintf(address.sun_path, sizeof address.sun_path, "%s", path.c_str());
    REQUIRE(::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0);
    const timeval timeout{0, 50'000};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  }
  ~NotifyListener() { ::close(fd_); }
  NotifyListener(const NotifyListener&) = delete;
  NotifyListener& operator=(const NotifyListener&) = delete;

  // Takes everything queued, waiting up to ~50 ms for the first datagram (`wait`) or not at all.
  void receive(bool wait = true) {
    char buffer[512];
    for (int flags = wait ? 0 : MSG_DONTWAIT;; flags = MSG_DONTWAIT) {
      const ssize_t n = ::recv(fd_, buffer, sizeof buffer, flags);
      if (n <= 0) return;
      messages_.emplace_back(buffer, static_cast<std::size_t>(n));
    }
  }
  // Polls `condition` until it holds or `limit` passes, taking the daemon's messages meanwhile,
  // as systemd reads its socket at once (a full socket would block the daemon's sd_notify).
  bool wait_for(const std::function<bool()>& condition, std::chrono::milliseconds limit) {
    return harness::wait_until(
        [&] {
          receive();
          return condition();
        },
        limit);
  }
  // Messages received so far that contain `text` (a datagram may carry several lines).
  std::size_t count(const std::string& text) const {
    std::size_t n = 0;
    for (const auto& m : messages_)
      n += m.find(text) != std::string::npos ? 1 : 0;
    return n;
  }
  // Index of the first message containing `text`, or the number of messages.
  std::size_t first(const std::string& text) const {
    for (std::size_t i = 0; i < messages_.size(); ++i)
      if (messages_[i].find(text) != std::string::npos) return i;
    return messages_.size();
  }
  std::string all() const {
    std::string text;
    for (const auto& m : messages_)
      text += m + "\n";
    return text;
  }

 private:
  int fd_ = -1;
  std::vector<std::string> messages_;
};

}  // namespace pandarcap::test
