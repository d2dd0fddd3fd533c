#include "core/decode/calibration.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bitset>
#include <charconv>
#include <cmath>
#include <type_traits>
#include <vector>

#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

Calibration Calibration::nominal(SensorModelId model) {
  Calibration calibration;
  with_model(model, [&]<class M>(std::type_identity<M>) {
    calibration.channel_count = M::kChannels;
    std::copy(M::kNominalElevationDeg.begin(), M::kNominalElevationDeg.end(),
              calibration.elevation_deg.begin());
    std::copy(M::kNominalAzimuthOffsetDeg.begin(), M::kNominalAzimuthOffsetDeg.end(),
              calibration.azimuth_offset_deg.begin());
  });
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

// Calls f(line_number, line) for every line of `text` that is not blank; returns the number of
// the last such line (0 for none).
template <class F>
std::size_t for_each_line(std::string_view text, F&& f) {
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
    f(line_number, raw);
  }
  return last_line;
}

// The first non-blank line is a header unless it already holds a numeric channel id.
bool is_header(std::string_view line) {
  double id = 0;
  return !parse_number(split_fields(line)[0].text, id);
}

// The rows a file holds (its non-blank lines less a header): said when an id is out of range,
// so a table of another model reads as that ("expected 40 channels ..., found 64").
std::size_t data_rows(std::string_view text) {
  std::size_t rows = 0;
  bool first = true;
  for_each_line(text, [&](std::size_t, std::string_view line) {
    if (!first || !is_header(line)) ++rows;
    first = false;
  });
  return rows;
}

}  // namespace

namespace {

// The table's rows, each checked where it stands (ids 1..expected); with `require_count`, exactly
// `expected` of them.
Calibration parse_table(std::string_view text, const std::string& source_name, int expected,
                        std::string_view model_name, bool require_count) {
  Calibration calibration;
  calibration.channel_count = expected;
  calibration.source = source_name;
  std::bitset<kMaxChannels> seen;
  std::array<std::size_t, kMaxChannels> seen_on_line{};
  bool header_done = false;

  const std::size_t last_line = for_each_line(text, [&](std::size_t line_number,
                                                        std::string_view raw) {
    if (!header_done) {
      header_done = true;
      if (is_header(raw)) return;
    }
    const std::vector<Field> fields = split_fields(raw);
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
    if (values[0] != std::floor(values[0]) || values[0] < 1 || values[0] > expected) {
      fail(source_name, line_number, fields[0].column,
           fmt::format("channel id must be an integer 1..{}, got '{}': expected {} channels ({}), "
                       "found {} rows",
                       expected, fields[0].text, expected, model_name, data_rows(text)));
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
  });

  const auto found = static_cast<int>(seen.count());
  if (require_count && found != expected) {
    std::string missing;
    for (int c = 0; c < expected; ++c) {
      if (!seen[c]) missing += fmt::format("{}{}", missing.empty() ? "" : ",", c + 1);
    }
    fail(source_name, last_line + 1, 1,
         fmt::format("expected {} channels ({}), found {}: {} of {} channels missing: {}", expected,
                     model_name, found, expected - found, expected, missing));
  }
  return calibration;
}

}  // namespace

Calibration Calibration::parse(std::string_view text, const std::string& source_name,
                               SensorModelId model) {
  return parse_table(text, source_name, pandarcap::channel_count(model), display_name(model), true);
}

Calibration Calibration::parse_any(std::string_view text, const std::string& source_name) {
  const std::size_t rows = data_rows(text);
  for (SensorModelId id : kSensorModelIds) {
    if (static_cast<std::size_t>(pandarcap::channel_count(id)) == rows) {
      return parse(text, source_name, id);
    }
  }
  // A line that is wrong where it stands is said first, at its line and column.
  parse_table(text, source_name, kMaxChannels, "a supported model", false);
  const std::size_t last_line = for_each_line(text, [](std::size_t, std::string_view) {});
  fail(source_name, last_line + 1, 1,
       fmt::format("{} channel rows: a table of a supported model has 16 (PandarXT16), 32 "
                   "(PandarXT32), 40 (Pandar40P), 64 (Pandar64) or 128 (PandarQT128)",
                   rows));
}

SensorModelId Calibration::model() const noexcept {
  for (SensorModelId id : kSensorModelIds) {
    if (pandarcap::channel_count(id) == channel_count) return id;
  }
  return SensorModelId::kPandar40P;
}

std::string Calibration::to_csv() const {
  std::string out = "Laser id,Elevation,Azimuth\n";
  for (int c = 0; c < channel_count; ++c) {
    out += fmt::format("{},{},{}\n", c + 1, elevation_deg[c], azimuth_offset_deg[c]);
  }
  return out;
}

}  // namespace pandarcap
