#include "daemon/ptc/sensor_queries.hpp"

#include <fmt/format.h>

#include <string_view>

namespace pandarcap {
namespace {

template <typename T, typename Parse>
Fetched<T> fetch(PtcClient& client, ptc::Command command, Parse parse,
                 std::span<const std::uint8_t> request = {},
                 bool unsupported_is_an_answer = false) {
  Fetched<T> out;
  PtcReply reply = client.request(command, request, unsupported_is_an_answer);
  if (!reply.ok()) {
    out.error = std::move(reply.error);
    return out;
  }
  ptc::Parsed<T> parsed = parse(reply.payload);
  if (!parsed.value) {
    out.error = client.fail(command, ptc::ErrorKind::kUnexpectedPayload, parsed.error);
    return out;
  }
  out.value = std::move(parsed.value);
  out.extra_bytes = parsed.extra_bytes;
  return out;
}

}  // namespace

Fetched<Calibration> fetch_calibration(PtcClient& client, std::optional<SensorModelId> model) {
  Fetched<Calibration> out;
  PtcReply reply = client.request(ptc::Command::kGetCalibration);
  if (!reply.ok()) {
    out.error = std::move(reply.error);
    return out;
  }
  std::string_view text(reinterpret_cast<const char*>(reply.payload.data()), reply.payload.size());
  // Some firmware terminates the text with NULs; nothing after them is table.
  if (const auto nul = text.find('\0'); nul != std::string_view::npos) text = text.substr(0, nul);
  try {
    out.value = Calibration::parse_for(text, "sensor " + client.endpoint(), model);
  } catch (const CalibrationError& error) {
    out.error =
        client.fail(ptc::Command::kGetCalibration, ptc::ErrorKind::kUnexpectedPayload,
                    fmt::format("not a {} calibration table: {}",
                                model ? display_name(*model) : "supported model's", error.what()));
  }
  return out;
}

Fetched<ptc::SensorInventory> fetch_inventory(PtcClient& client) {
  return fetch<ptc::SensorInventory>(client, ptc::Command::kGetInventory, &ptc::parse_inventory);
}

Fetched<ptc::SensorSettings> fetch_settings(PtcClient& client) {
  return fetch<ptc::SensorSettings>(client, ptc::Command::kGetConfig, &ptc::parse_settings);
}

Fetched<ptc::SensorStatus> fetch_status(PtcClient& client) {
  return fetch<ptc::SensorStatus>(client, ptc::Command::kGetStatus, &ptc::parse_status);
}

Fetched<ptc::PtpDiagnostics> fetch_ptp_status(PtcClient& client) {
  static constexpr std::uint8_t kQuery[] = {ptc::kPtpQueryStatus};
  return fetch<ptc::PtpDiagnostics>(client, ptc::Command::kPtpDiagnostics, &ptc::parse_ptp_status,
                                    kQuery, true);
}

}  // namespace pandarcap
