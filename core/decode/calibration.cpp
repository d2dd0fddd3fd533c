#include "core/decode/calibration.hpp"

#include <fmt/format.h>

#include <bitset>
#include <charconv>
#include <cmath>
#include <vector>

namespace pandarcap {

Calibration Calibration::nominal() {
  // Design elevations (MAN40 Appendix I, Hesai General SDK default). The General SDK has -1.66
  // for channel 17; every neighbouring step is 1/3 degree, so the design value -1.67 is used.
  static constexpr std::array<double, kChannels> kElevation = {
      15.0, 11.0,  8.0,   5.0,   3.0,   2.0,   1.67,  1.33,  1.0,   0.67,
      0.33, 0.0,   -0.33, -0.67, -1.0,  -1.33, -1.67, -2.0,  -2.33, -2.67,
      -3.0, -3.33, -3.67, -4.0,  -4.33, -4.67, -5.0,  -5.33, -5.67, -6.0,
      -7.0, -8.0,  -9.0,  -10.0, -11.0, -12.0, -13.0, -14.0, -19.0, -25.0};
  Calibration calibration;
  calibration.elevation_deg = kElevation;
  for (int c = 0; c < kChannels; ++c) {
    // Channels 1-6 and 31-40 sit at -1.042°; channels 7-30 cycle +3.125, -5.208, -1.042.
    double offset = -1.042;
    if (c >= 6 && c < 30) {
      static constexpr double kCycle[3] = {3.125, -5.208, -1.042};
      offset = kCycle[(c - 6) % 3];
    }
    calibration.azimuth_offset_deg[c] = offset;
  }
  calibration.source = "nominal";
  return calibration;
}

namespace {

struct Field {
  std::string_view text;
  std::size_t column = 1;  // 1-based column of the field's first character
};

std::string_view trim(std::string_view s, std::size_t* leading = nullptr) {
  std::size_t begin = 0;
  while (begin < s.size() && (s[begin] == ' ' || s[begin] == '\t'))
    ++begin;
  std::size_t end = s.size();
  while (end > begin && (s[end - 1] == ' ' || s[end - 1] == '\t' || s[end - 1] == '\r'))
    --end;
  if (leading != nullptr) *leading = begin;
  return s.substr(begin, end - begin);
}

std::vector<Field> split_fields(std::string_view line) {
  std::vector<Field> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    const std::string_view raw =
        line.substr(start, comma == std::string_view::npos ? line.npos : comma - start);
    std::size_t leading = 0;
    const std::string_view text = trim(raw, &leading);
    fields.push_back({text, start + leading + 1});
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return fields;
}

bool parse_number(std::string_view text, double& value) {
  // from_chars takes no '+': one is allowed, and only before a digit or '.' ("+-1" is no number).
  if (!text.empty() && text.front() == '+') {
    text.remove_prefix(1);
    if (text.empty() || text.front() == '-' || text.front() == '+') return false;
  }
  const char* end = text.data() + text.size();
  const auto result = std::from_chars(text.data(), end, value);
  return !text.empty() && result.ec == std::errc() && result.ptr == end && std::isfinite(value);
}

[[noreturn]] void fail(const std::string& source, std::size_t line, std::size_t column,
                       std::string_view message) {
  throw CalibrationError(fmt::format("{}:{}:{}: {}", source, line, column, message));
}

}  // namespace

Calibration Calibration::parse(std::string_view text, const std::string& source_name) {
  Calibration calibration;
  calibration.source = source_name;
  std::bitset<kChannels> seen;
  std::array<std::size_t, kChannels> seen_on_line{};
  bool header_done = false;
  std::size_t line_number = 0;
  std::size_t last_line = 0;

  std::size_t pos = 0;
  while (pos <= text.size()) {
    const std::size_t newline = text.find('\n', pos);
    const std::string_view raw =
        text.substr(pos, newline == std::string_view::npos ? text.npos : newline - pos);
    pos = newline == std::string_view::npos ? text.size() + 1 : newline + 1;
    ++line_number;
    if (trim(raw).empty()) continue;
    last_line = line_number;

    const std::vector<Field> fields = split_fields(raw);
    double id_value = 0;
    if (!header_done) {
      header_done = true;
      // The first non-blank line is a header unless it already holds a numeric channel id.
      if (!parse_number(fields[0].text, id_value)) continue;
    }
    if (fields.size() != 3) {
      fail(source_name, line_number, 1,
           fmt::format("expected 3 fields (id,elevation,azimuth), found {}", fields.size()));
    }
    double values[3] = {};
    static constexpr std::string_view kNames[3] = {"channel id", "elevation", "azimuth offset"};
    for (int i = 0; i < 3; ++i) {
      if (!parse_number(fields[i].text, values[i])) {
        fail(source_name, line_number, fields[i].column,
             fmt::format("{} is not a number: '{}'", kNames[i], fields[i].text));
      }
    }
    if (values[0] != std::floor(values[0]) || values[0] < 1 || values[0] > kChannels) {
      fail(source_name, line_number, fields[0].column,
           fmt::format("channel id must be an integer 1..{}, got '{}'", kChannels, fields[0].text));
    }
    const int channel = static_cast<int>(values[0]) - 1;
    if (seen[channel]) {
      fail(
          source_name, line_number, fields[0].column,
          fmt::format("channel {} already defined on line {}", channel + 1, seen_on_line[channel]));
    }
    if (values[1] < -90.0 || values[1] > 90.0) {
      fail(source_name, line_number, fields[1].column,
           fmt::format("elevation {} is outside -90..90 degrees", fields[1].text));
    }
    if (values[2] < -180.0 || values[2] > 180.0) {
      fail(source_name, line_number, fields[2].column,
           fmt::format("azimuth offset {} is outside -180..180 degrees", fields[2].text));
    }
    seen[channel] = true;
    seen_on_line[channel] = line_number;
    calibration.elevation_deg[channel] = values[1];
    calibration.azimuth_offset_deg[channel] = values[2];
  }

  if (!seen.all()) {
    std::string missing;
    for (int c = 0; c < kChannels; ++c) {
      if (!seen[c]) missing += fmt::format("{}{}", missing.empty() ? "" : ",", c + 1);
    }
    fail(
        source_name, last_line + 1, 1,
        fmt::format("{} of {} channels missing: {}", kChannels - seen.count(), kChannels, missing));
  }
  return calibration;
}

std::string Calibration::to_csv() const {
  std::string out = "Laser id,Elevation,Azimuth\n";
  for (int c = 0; c < kChannels; ++c) {
    out += fmt::format("{},{},{}\n", c + 1, elevation_deg[c], azimuth_offset_deg[c]);
  }
  return out;
}

}  // namespace pandarcap
