#include "daemon/output/standing_problems.hpp"

#include <fmt/format.h>

#include <cerrno>
#include <cstring>
#include <iterator>

namespace pandarcap {

void describe_standing_problems(const ReceiveCounters& receive, const live::LiveCounters* live,
                                std::string& out) {
  out.clear();
  const auto to = std::back_inserter(out);
  using End = ReceiveCounters::CaptureEnd;
  // acquire: the text each flag guards was written before it was set.
  const End end = receive.capture_end.load(std::memory_order_acquire);
  const bool named = receive.capture_damage_named.load(std::memory_order_acquire);
  if (end == End::kTruncated) {
    fmt::format_to(to, "recording cut short: {}", receive.capture_end_text);
  } else if (end == End::kDamaged && receive.capture_end_text[0] != '\0') {
    fmt::format_to(to, "recording damaged: {}", receive.capture_end_text);
  } else if (named) {
    fmt::format_to(to, "recording damaged: {}", receive.capture_first_damage);
  }
  if (!out.empty()) {
    const std::uint64_t chunks = receive.capture_chunks_skipped.load(std::memory_order_relaxed);
    const std::uint64_t packets = receive.capture_packets_skipped.load(std::memory_order_relaxed);
    const std::uint64_t lengths = receive.capture_records_damaged.load(std::memory_order_relaxed);
    const std::uint64_t headers = receive.capture_records_malformed.load(std::memory_order_relaxed);
    const char* separator = " (";
    const auto part = [&]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
      out += separator;
      fmt::format_to(to, format, std::forward<Args>(args)...);
      separator = ", ";
    };
    if (chunks > 0)
      part("{} damaged chunk{} skipped, {} packets in them", chunks, chunks == 1 ? "" : "s",
           packets);
    if (lengths > 0) part("{} damaged record length{} read over", lengths, lengths == 1 ? "" : "s");
    if (headers > 0)
      part("{} record{} with damaged headers skipped", headers, headers == 1 ? "" : "s");
    if (separator[0] == ',') out += ')';
  }
  if (live != nullptr && !live->listening.load(std::memory_order_relaxed)) {
    if (!out.empty()) out += "; ";
    const int error = live->listen_errno.load(std::memory_order_relaxed);
    const unsigned port = live->port.load(std::memory_order_relaxed);
    const double retry_s = live->listen_retry_ms.load(std::memory_order_relaxed) / 1000.0;
    if (error == EADDRINUSE) {
      fmt::format_to(to, "live view: port {} in use (retrying every {:g} s)", port, retry_s);
    } else {
      const char* text = ::strerrordesc_np(error);
      fmt::format_to(to, "live view: cannot listen on port {}: {} (retrying every {:g} s)", port,
                     text != nullptr ? text : "unknown error", retry_s);
    }
  }
}

}  // namespace pandarcap
