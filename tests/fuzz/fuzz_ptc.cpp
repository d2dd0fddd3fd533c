// Fuzz target: PTC responses as a sensor (or anything at its address) might send them. The first
// byte picks the command the "request" was; the next 8 are the response header; the rest is the
// payload. The header is checked as the client checks it, and a payload it would accept is
// decoded as that command's answer (the calibration as a calibration table).
//
// Invariants, beyond "no crash, no UB":
//   - an accepted header has the magic, echoes the command and announces no more than the bound;
//   - status/config parse exactly when long enough, and encoding what was parsed gives back the
//     payload's known bytes (nothing read from the wrong offset);
//   - inventory strings stay within their fields and hold only printable characters.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string_view>

#include "core/decode/calibration.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/ptc_protocol.hpp"

using namespace pandarcap;

namespace {

constexpr std::uint32_t kMaxPayload = 64 * 1024;
constexpr ptc::Command kCommands[] = {ptc::Command::kGetCalibration, ptc::Command::kGetInventory,
                                      ptc::Command::kGetConfig, ptc::Command::kGetStatus};

void require(bool condition) {
  if (!condition) std::abort();
}

bool printable(const std::string& s, std::size_t field) {
  if (s.size() > field) return false;
  for (const char c : s)
    if (c < 0x20 || c > 0x7E) return false;
  return true;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1 + ptc::kHeaderBytes) return 0;
  const ptc::Command command = kCommands[data[0] % std::size(kCommands)];
  const std::span<const std::uint8_t, ptc::kHeaderBytes> head(data + 1, ptc::kHeaderBytes);
  const std::span<const std::uint8_t> rest(data + 1 + ptc::kHeaderBytes,
                                           size - 1 - ptc::kHeaderBytes);
  const ptc::ResponseHeader h = ptc::decode_header(head);
  if (const auto problem = ptc::check_response_header(h, head, command, kMaxPayload)) {
    require(!problem->message.empty());
    return 0;
  }
  require(head[0] == 0x47 && head[1] == 0x74);
  require(h.command == static_cast<std::uint8_t>(command));
  require(h.payload_length <= kMaxPayload);
  // What the client would have read: the announced length, or what arrived before the end.
  const std::span<const std::uint8_t> payload =
      rest.first(std::min<std::size_t>(rest.size(), h.payload_length));

  switch (command) {
    case ptc::Command::kGetStatus: {
      const auto parsed = ptc::parse_status(payload);
      require(parsed.value.has_value() == (payload.size() >= ptc::kStatusBytes));
      if (parsed.value) {
        const auto again = ptc::encode_status(*parsed.value);
        require(std::equal(again.begin(), again.begin() + 49, payload.begin()));
        require(parsed.extra_bytes == payload.size() - ptc::kStatusBytes);
      }
      break;
    }
    case ptc::Command::kGetConfig: {
      const auto parsed = ptc::parse_settings(payload);
      require(parsed.value.has_value() == (payload.size() >= ptc::kConfigBytes));
      if (parsed.value) {
        const auto again = ptc::encode_settings(*parsed.value);
        require(std::equal(again.begin(), again.begin() + 41, payload.begin()));
      }
      break;
    }
    case ptc::Command::kGetInventory: {
      const auto parsed = ptc::parse_inventory(payload);
      require(parsed.value.has_value() == (payload.size() >= ptc::kInventoryBytes));
      if (parsed.value) {
        const ptc::SensorInventory& v = *parsed.value;
        require(printable(v.serial, 18) && printable(v.manufacture_date, 16) &&
                printable(v.software_version, 16) && printable(v.hardware_version, 16) &&
                printable(v.control_firmware, 16) && printable(v.sensor_firmware, 16));
      }
      break;
    }
    case ptc::Command::kGetCalibration: {
      const std::string_view text(reinterpret_cast<const char*>(payload.data()), payload.size());
      try {
        const Calibration c = Calibration::parse(text, "fuzz");
        for (int ch = 0; ch < kChannels; ++ch) {
          require(std::isfinite(c.elevation_deg[ch]) && std::isfinite(c.azimuth_offset_deg[ch]));
        }
      } catch (const CalibrationError&) {
      }
      break;
    }
    case ptc::Command::kPtpDiagnostics:
      break;
  }
  return 0;
}
