#include "daemon/ptc/sensor_status_poller.hpp"

#include <spdlog/spdlog.h>

#include "core/ptc/status_plausibility.hpp"
#include "daemon/clocks.hpp"
#include "daemon/ptc/sensor_queries.hpp"

namespace pandarcap {

SensorStatusPoller::SensorStatusPoller(PtcClientOptions options, std::chrono::milliseconds interval,
                                       SensorStatusChannel& channel,
                                       std::optional<std::uint8_t> clock_source)
    : client_(std::move(options)),
      interval_(interval),
      channel_(channel),
      clock_source_(clock_source),
      base_requests_(channel.requests.load()),
      base_errors_(channel.errors.load()) {}

void SensorStatusPoller::run() {
  for (std::uint64_t round = 0;; ++round) {
    poll_once(round);
    std::unique_lock lock(mutex_);
    if (wake_.wait_for(lock, interval_, [&] { return stop_; })) return;
  }
}

void SensorStatusPoller::stop() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
}

void SensorStatusPoller::poll_once(std::uint64_t round) {
  if (!clock_source_ || round % 12 == 0) {
    const Fetched<ptc::SensorSettings> settings = fetch_settings(client_);
    if (settings.value) clock_source_ = settings.value->clock_source;
  }
  std::optional<std::int64_t> ptp_offset_ns;
  if (ask_ptp_diagnostics_) {
    const Fetched<ptc::PtpDiagnostics> ptp = fetch_ptp_status(client_);
    if (ptp.value) {
      ptp_offset_ns = ptp.value->master_offset_ns;
    } else if (ptp.error->kind == ptc::ErrorKind::kErrorCode ||
               ptp.error->kind == ptc::ErrorKind::kUnexpectedPayload) {
      spdlog::info("sensor status: no PTP offset ({}); the status's PTP state is used",
                   ptp.error->message);
      ask_ptp_diagnostics_ = false;
    }
  }
  const Fetched<ptc::SensorStatus> status = fetch_status(client_);
  channel_.requests.store(base_requests_ + client_.requests(), std::memory_order_relaxed);
  channel_.errors.store(base_errors_ + client_.errors(), std::memory_order_relaxed);
  if (status.value) {
    if (!answering_) spdlog::info("sensor status: {} answers again", client_.endpoint());
    if (status.extra_bytes > 0 && round == 0) {
      spdlog::info("sensor status: {} bytes more than the Pandar40P layout (newer firmware?)",
                   status.extra_bytes);
    }
    answering_ = true;
    const std::uint32_t implausible = ptc::implausible_fields(*status.value);
    if (implausible != 0) channel_.implausible.fetch_add(1, std::memory_order_relaxed);
    if (implausible != implausible_) {
      // Once per change, not per answer: the health says it every second.
      if (implausible != 0) {
        std::string what;
        ptc::describe_implausible(*status.value, implausible, what);
        spdlog::warn("sensor status: implausible values left out: {}", what);
      } else {
        spdlog::info("sensor status: every value plausible again");
      }
      implausible_ = implausible;
    }
    channel_.samples.try_push(
        SensorStatusSample{monotonic_ns(), *status.value, clock_source_, ptp_offset_ns});
    return;
  }
  if (answering_) {
    spdlog::warn("sensor status: {}; asking again every {} ms", status.error->message,
                 interval_.count());
  }
  answering_ = false;
}

}  // namespace pandarcap
