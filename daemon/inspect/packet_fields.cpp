#include "daemon/inspect/packet_fields.hpp"

#include <fmt/format.h>

#include <type_traits>

#include "core/sensors/sensor_models.hpp"

namespace pandarcap {
namespace {

using nlohmann::json;

std::string format_utc(const PacketDateTime& utc) {
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z", utc.year, utc.month, utc.day, utc.hour,
                     utc.minute, utc.second);
}

json optional_json(const auto& value) {
  return value ? json(*value) : json(nullptr);
}

// The fields every model has, then its own.
template <class M>
void model_fields(json& j, std::span<const std::uint8_t> p) {
  j["markers_ok"] = true;
  j["azimuth_first_cdeg"] = M::azimuth_cdeg(p, 0);
  j["azimuth_last_cdeg"] = M::azimuth_cdeg(p, M::kBlocks - 1);
  j["rpm"] = M::motor_rpm(p);
  j["timestamp_us"] = M::timestamp_us(p);
  j["return_mode"] = to_string(M::return_mode(p));
  j["factory"] = M::factory(p);
  j["utc"] = format_utc(M::utc(p));
  j["sequence"] = optional_json(M::sequence(p));
  if constexpr (std::is_same_v<M, Pandar40P>) {
    const Tail tail = PacketView::assume_valid(p).tail();
    j["status_id"] = tail.status_id;
    j["status_value"] = tail.status_value;
  }
  // A model with a firing-sequence flag and a functional-safety block (the QT128) says them.
  if constexpr (requires { M::mode_flag(p), M::functional_safety_state(p); }) {
    j["mode_flag"] = M::mode_flag(p);
    j["functional_safety_state"] = optional_json(M::functional_safety_state(p));
    j["functional_safety_counter"] = optional_json(M::functional_safety_counter(p));
  }
  j["high_temperature"] = M::high_temperature(p);
}

std::string or_dash(const json& value) {
  return value.is_null() ? std::string("-") : value.dump();
}

}  // namespace

json packet_json(SensorModelId model, std::uint64_t index, const CaptureRecord& record,
                 RejectReason reason, bool has_endpoints) {
  json j;
  j["index"] = index;
  j["record_time_ns"] = record.timestamp_ns;
  // An MCAP file's packets have no addresses.
  j["source"] = has_endpoints ? json(to_string(record.source)) : json(nullptr);
  j["destination"] = has_endpoints ? json(to_string(record.destination)) : json(nullptr);
  j["size"] = record.payload.size();
  if (record.snapped) j["original_size"] = record.udp_payload_length;  // the file holds a part
  j["status"] = reason == RejectReason::kNone ? "ok" : std::string(to_string(reason));
  if (reason != RejectReason::kNone) return j;
  with_model(model, [&]<class M>(std::type_identity<M>) { model_fields<M>(j, record.payload); });
  return j;
}

std::string packet_heading(SensorModelId model) {
  // az0 and the last block's: az9 on a 40P, az5 on a Pandar64, az7 on an XT, az1 on a QT128.
  const std::string last = fmt::format(
      "az{}", with_model(model, []<class M>(std::type_identity<M>) { return M::kBlocks - 1; }));
  std::string heading =
      fmt::format("{:>6} {:>5} {:>7} {:>7} {:>5} {:>8} {:>9} {:>4} {:20} {:>10}", "#", "size",
                  "az0", last, "rpm", "us", "mode", "fac", "utc", "sequence");
  if (model == SensorModelId::kPandar40P) heading += fmt::format(" {:>3} {:>5}", "sid", "svalue");
  if (model == SensorModelId::kPandarQT128) heading += fmt::format(" {:>4} {:>2}", "flag", "fs");
  return heading;
}

std::string packet_line(SensorModelId model, const json& p) {
  if (p["status"] != "ok") {
    return fmt::format("{:>6} {:>5} REJECTED {}", p["index"].get<std::uint64_t>(),
                       p["size"].get<std::size_t>(), p["status"].get<std::string>());
  }
  std::string line =
      fmt::format("{:>6} {:>5} {:>7.2f} {:>7.2f} {:>5} {:>8} {:>9} 0x{:02x} {} {:>10}",
                  p["index"].get<std::uint64_t>(), p["size"].get<std::size_t>(),
                  p["azimuth_first_cdeg"].get<int>() / 100.0,
                  p["azimuth_last_cdeg"].get<int>() / 100.0, p["rpm"].get<int>(),
                  p["timestamp_us"].get<std::uint32_t>(), p["return_mode"].get<std::string>(),
                  p["factory"].get<int>(), p["utc"].get<std::string>(), or_dash(p["sequence"]));
  if (model == SensorModelId::kPandar40P) {
    line += fmt::format(" {:>3} {:>5}", p["status_id"].get<int>(), p["status_value"].get<int>());
  }
  if (model == SensorModelId::kPandarQT128) {
    line += fmt::format(" 0x{:02x} {:>2}", p["mode_flag"].get<int>(),
                        or_dash(p["functional_safety_state"]));
  }
  if (p["high_temperature"].get<bool>()) line += " HIGH-TEMP";
  return line;
}

}  // namespace pandarcap
