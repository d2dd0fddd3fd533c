// The sensor models (core/sensors/pandar*.hpp) read against the real captures: every packet of
// each capture validates as its model and is detected as it, and its fields read what
// /work/research/hesai-models.md found in the same bytes with its own scripts (return mode,
// motor speed, dates and their year rules, the time and azimuth steps from packet to packet,
// packets per revolution, the QT128's CRCs, mode flag and firing sequences). The rates the
// models compute from their firing periods are checked against what the captures show, so a
// wrong period or block count fails here.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/packet_time.hpp"
#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_models.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

using Payloads = std::vector<std::vector<std::uint8_t>>;

// What the research's scripts read off each capture (hesai-models.md §2.1-2.4).
struct CaptureFacts {
  const char* file;
  std::size_t packets;
  std::size_t bytes;
  int rpm_min, rpm_max;
  PacketDateTime first_date, last_date;
  std::optional<std::uint32_t> first_sequence;  // then +1 each packet
  int packets_per_revolution;                   // between two zero crossings
};

std::int64_t unix_us(const PacketDateTime& d, std::uint32_t timestamp_us) {
  const std::int64_t seconds =
      days_from_civil(d.year, d.month, d.day) * 86'400 + d.hour * 3'600 + d.minute * 60 + d.second;
  return seconds * 1'000'000 + timestamp_us;
}

std::int64_t step_cdeg(std::uint16_t from, std::uint16_t to) {
  return test::floor_mod(static_cast<std::int64_t>(to) - from, test::kCircle);
}

// The checks every model's capture passes; returns its payloads for the model's own checks.
template <class M>
Payloads check_capture(const CaptureFacts& facts) {
  INFO(display_name(M::kId) << ": " << facts.file);
  const auto path = test::real_capture(facts.file);
  if (!path) return {};
  const Payloads payloads = test::capture_payloads(*path);
  REQUIRE(payloads.size() == facts.packets);

  const double period_us = static_cast<double>(M::packet_period_ns(2)) / 1000.0;
  // Rounded, not truncated: the QT128's 111.11 µs at 600 RPM is 39.9996 × 0.01°.
  const std::int64_t packet_step = std::lround(M::azimuth_step_per_packet_cdeg(2, 600));
  const std::int64_t firing_step = std::lround(M::azimuth_step_per_firing_cdeg(600));
  std::map<std::int64_t, int> packet_steps, firing_steps;
  std::vector<std::size_t> crossings;
  double dt_sum_us = 0;
  for (std::size_t i = 0; i < payloads.size(); ++i) {
    const std::span<const std::uint8_t> p = payloads[i];
    INFO("packet " << i);
    REQUIRE(p.size() == facts.bytes);
    REQUIRE(M::validate(p) == RejectReason::kNone);
    const DetectedModel detected = detect_model(p);
    REQUIRE(detected.kind == DetectionKind::kKnown);
    REQUIRE(detected.model == M::kId);
    CHECK(M::return_mode(p) == ReturnMode::kDual);
    CHECK(returns_per_firing(M::return_mode(p)) == 2);
    CHECK(M::motor_rpm(p) >= facts.rpm_min);
    CHECK(M::motor_rpm(p) <= facts.rpm_max);
    CHECK(M::distance_unit_m(p) == 0.004);
    CHECK(M::factory(p) == 0x42);
    CHECK_FALSE(M::high_temperature(p));
    if (facts.first_sequence) {
      REQUIRE(M::sequence(p));
      CHECK(*M::sequence(p) == *facts.first_sequence + i);
    } else {
      CHECK_FALSE(M::sequence(p));
    }
    // Dual return: each firing's two blocks have one azimuth.
    for (int b = 0; b < M::kBlocks; b += 2)
      CHECK(M::azimuth_cdeg(p, b) == M::azimuth_cdeg(p, b + 1));
    if (M::kBlocks > 2) ++firing_steps[step_cdeg(M::azimuth_cdeg(p, 0), M::azimuth_cdeg(p, 2))];
    if (i == 0) continue;
    const std::span<const std::uint8_t> q = payloads[i - 1];
    const std::int64_t dt_us =
        unix_us(M::utc(p), M::timestamp_us(p)) - unix_us(M::utc(q), M::timestamp_us(q));
    CHECK(std::abs(static_cast<double>(dt_us) - period_us) <= 1.5);
    dt_sum_us += static_cast<double>(dt_us);
    ++packet_steps[step_cdeg(M::azimuth_cdeg(q, 0), M::azimuth_cdeg(p, 0))];
    if (M::azimuth_cdeg(p, 0) < M::azimuth_cdeg(q, 0)) crossings.push_back(i);
  }
  CHECK(M::utc(payloads.front()) == facts.first_date);
  CHECK(M::utc(payloads.back()) == facts.last_date);
  // The mean period is the model's to 0.05 % (the sensor's clock, not the receive times).
  CHECK(dt_sum_us / static_cast<double>(payloads.size() - 1) == Approx(period_us).epsilon(5e-4));
  // The packet's azimuth step: the model's at 600 RPM most often, never more than 2 off it.
  const auto most_common = [](const std::map<std::int64_t, int>& counts) {
    return std::max_element(counts.begin(), counts.end(),
                            [](auto& a, auto& b) { return a.second < b.second; })
        ->first;
  };
  CHECK(most_common(packet_steps) == packet_step);
  CHECK(packet_steps.begin()->first >= packet_step - 2);
  CHECK(packet_steps.rbegin()->first <= packet_step + 2);
  if (M::kBlocks > 2) {
    CHECK(most_common(firing_steps) == firing_step);
    CHECK(firing_steps.begin()->first >= firing_step - 2);
    CHECK(firing_steps.rbegin()->first <= firing_step + 2);
  }
  // Packets from one zero crossing to the next: the model's count at 600 RPM (±1: where in a
  // packet the crossing falls).
  REQUIRE(crossings.size() >= 2);
  for (std::size_t k = 1; k < crossings.size(); ++k) {
    const auto revolution = static_cast<int>(crossings[k] - crossings[k - 1]);
    CHECK(std::abs(revolution - facts.packets_per_revolution) <= 1);
  }
  CHECK(M::packets_per_revolution(2, 600) == Approx(facts.packets_per_revolution).epsilon(1e-3));
  return payloads;
}

}  // namespace

TEST_CASE("the Pandar40P capture: every packet a Pandar40P, fields as the research read them",
          "[sensors][real]") {
  const Payloads payloads =
      check_capture<Pandar40P>({"pandar40p_nebula_dual_600rpm_1262B.pcap", 1439, 1262, 598, 602,
                                PacketDateTime{2017, 9, 6, 16, 19, 46},
                                PacketDateTime{2017, 9, 6, 16, 19, 47}, std::nullopt, 360});
  // The model's accessors are PacketView's (its bytes out must not change); the offsets it
  // declares for the generic code must name the same bytes PacketView reads.
  for (const auto& bytes : payloads) {
    const std::span<const std::uint8_t> p = bytes;
    const PacketView view = PacketView::assume_valid(p);
    for (int b = 0; b < Pandar40P::kBlocks; ++b) {
      const std::uint8_t* block =
          p.data() + Pandar40P::kHeaderBytes + Pandar40P::kBlockBytes * static_cast<std::size_t>(b);
      REQUIRE(load_u16_le(block + Pandar40P::kBlockAzimuthOffset) == view.azimuth_cdeg(b));
      for (int c = 0; c < Pandar40P::kChannels; ++c) {
        const std::uint8_t* unit = block + Pandar40P::kFirstUnitOffset +
                                   Pandar40P::kUnitBytes * static_cast<std::size_t>(c);
        REQUIRE(load_u16_le(unit) == view.distance_raw(b, c));
        REQUIRE(unit[2] == view.reflectivity(b, c));
      }
    }
    REQUIRE(load_u16_le(p.data() + Pandar40P::kMotorSpeedOffset) == view.motor_rpm());
    REQUIRE(load_u32_le(p.data() + Pandar40P::kTimestampOffset) == view.timestamp_us());
    REQUIRE(p[Pandar40P::kReturnModeOffset] == static_cast<std::uint8_t>(view.return_mode()));
    REQUIRE(p[Pandar40P::kDateTimeOffset] == view.utc().year_since_2000);
    REQUIRE((p[Pandar40P::kHighTemperatureOffset] != 0) == view.tail().high_temperature);
  }
}

TEST_CASE("the Pandar64 capture: every packet a Pandar64, its year counted the SDK's way",
          "[sensors][real]") {
  const Payloads payloads =
      check_capture<Pandar64>({"pandar64_nebula_dual_1198B.pcap", 2400, 1198, 598, 602,
                               PacketDateTime{2020, 6, 25, 12, 2, 9},
                               PacketDateTime{2020, 6, 25, 12, 2, 10}, 2339721u, 600});
  if (payloads.empty()) return;
  // Raw year 120: 1900 + 120 by Hesai's SDK, where nebula's 2000 + raw says 2120.
  CHECK(payloads[0][Pandar64::kDateTimeOffset] == 120);
  CHECK(payloads[0][Pandar64::kLaserCountOffset] == 0x40);
  CHECK(payloads[0][Pandar64::kBlockCountOffset] == 6);
}

TEST_CASE("the PandarXT32 capture: every packet an XT32, header and confidence as read",
          "[sensors][real]") {
  const Payloads payloads =
      check_capture<PandarXT32>({"pandarxt32_nebula_dual_1080B.pcap", 2000, 1080, 599, 600,
                                 PacketDateTime{2019, 7, 25, 3, 19, 29},
                                 PacketDateTime{2019, 7, 25, 3, 19, 30}, 301676u, 500});
  if (payloads.empty()) return;
  const std::vector<std::uint8_t> header = {0xEE, 0xFF, 0x06, 0x01, 0x00, 0x00,
                                            0x20, 0x08, 0x01, 0x04, 0x02, 0x01};
  for (const auto& bytes : payloads) {
    REQUIRE(std::equal(header.begin(), header.end(), bytes.begin()));
    for (int b = 0; b < PandarXT32::kBlocks; ++b) {
      for (int c = 0; c < PandarXT32::kChannels; ++c)
        REQUIRE(PandarXT32::confidence(bytes, b, c) == 255);
    }
  }
  CHECK(payloads[0][PandarXT32::kDateTimeOffset] == 119);  // 1900 + 119
  // The XT16's layout is the XT32's with 16 channels: the same tail at its own offsets.
  CHECK(PandarXT16::kTailOffset == 540);
  CHECK(PandarXT16::kReturnModeOffset == 550);
  CHECK(PandarXT16::kSequenceOffset == 564);
  CHECK(PandarXT16::kMaxDatagramBytes == 568);
  CHECK(PandarXT32::kReturnModeOffset == 1062);
  CHECK(PandarXT32::kSequenceOffset == 1076);
}

TEST_CASE(
    "the PandarQT128 capture: every packet a QT128, CRCs valid, the mode flag choosing the "
    "firing sequence whose channels are not zero",
    "[sensors][real]") {
  const Payloads payloads =
      check_capture<PandarQT128>({"pandarqt128_nebula_laststrongest_1127B.pcap", 1800, 1127, 600,
                                  600, PacketDateTime{2020, 10, 9, 12, 3, 29},
                                  PacketDateTime{2020, 10, 9, 12, 3, 29}, 6394573u, 900});
  if (payloads.empty()) return;
  const std::vector<std::uint8_t> header = {0xEE, 0xFF, 0x03, 0x02, 0x03, 0x00,
                                            0x80, 0x02, 0x01, 0x04, 0x02, 0x1D};
  const PandarQT128::Layout l = PandarQT128::layout(0x1D);
  CHECK(l.unit_bytes == 4);
  CHECK(l.body_crc_offset == 1040);
  CHECK(l.functional_safety_offset == 1044u);
  CHECK(l.tail_offset == 1061);
  CHECK(l.sequence_offset == 1087u);
  CHECK(l.tail_crc_offset == 1091);
  CHECK(l.datagram_bytes == 1127);

  std::array<int, 2> flags{};
  std::set<int> counters;
  for (std::size_t i = 0; i < payloads.size(); ++i) {
    const std::span<const std::uint8_t> p = payloads[i];
    INFO("packet " << i);
    REQUIRE(std::equal(header.begin(), header.end(), p.begin()));
    const std::uint8_t flag = PandarQT128::mode_flag(p);
    REQUIRE(flag <= 1);
    ++flags[flag];
    if (i > 0) CHECK(flag != PandarQT128::mode_flag(payloads[i - 1]));  // alternates
    CHECK(PandarQT128::functional_safety_state(p) == std::uint8_t{0});
    counters.insert(*PandarQT128::functional_safety_counter(p));
    // A dual packet is one firing: both blocks one sequence, the one the flag says. The
    // channels it does not fire are zero: 32-63 in sequence 2 (flag 0), 0-31 in sequence 1.
    const int sequence = PandarQT128::firing_sequence(flag, 0, 2);
    CHECK(PandarQT128::firing_sequence(flag, 1, 2) == sequence);
    CHECK(sequence == (flag == 1 ? 1 : 2));
    for (int b = 0; b < PandarQT128::kBlocks; ++b) {
      for (int c = 0; c < PandarQT128::kChannels; ++c) {
        if (!PandarQT128::fires(sequence, c)) {
          REQUIRE(PandarQT128::distance_raw(p, b, c) == 0);
          REQUIRE(PandarQT128::reflectivity(p, b, c) == 0);
        }
      }
    }
  }
  CHECK(flags[0] == 900);
  CHECK(flags[1] == 900);
  CHECK(counters == std::set<int>{0, 1, 2, 3, 4, 5});
  // The channels both sequences fire (64-127) do return, in packets of either flag.
  for (const int flag : {0, 1}) {
    std::size_t returns = 0;
    for (const auto& bytes : payloads) {
      if (PandarQT128::mode_flag(bytes) != flag) continue;
      for (int c = 64; c < 128; ++c)
        returns += PandarQT128::distance_raw(bytes, 0, c) != 0 ? 1 : 0;
    }
    INFO("flag " << flag);
    CHECK(returns > 900 * 64 / 2);
  }
}

TEST_CASE(
    "a QT128 packet with any byte flipped under a CRC is bad_crc, the bytes outside are not "
    "covered",
    "[sensors][real]") {
  const auto path = test::real_capture("pandarqt128_nebula_laststrongest_1127B.pcap");
  if (!path) return;
  const std::vector<std::uint8_t> packet = test::capture_payloads(*path).at(0);
  REQUIRE(PandarQT128::validate(packet) == RejectReason::kNone);
  // Under the body CRC (blocks: 12..1039), the FS CRC (1045..1056), the tail CRC (1061..1090),
  // and each CRC itself.
  for (const std::size_t at : {12u, 14u, 500u, 1039u, 1040u, 1043u, 1045u, 1050u, 1056u, 1057u,
                               1060u, 1061u, 1066u, 1073u, 1082u, 1087u, 1090u, 1091u, 1094u}) {
    std::vector<std::uint8_t> bad = packet;
    bad[at] ^= 0x01;
    INFO("byte " << at);
    CHECK(PandarQT128::validate(bad) == RejectReason::kBadCrc);
    CHECK(detect_model(bad).kind == DetectionKind::kUnknown);
    CHECK(detect_model(bad).reject == RejectReason::kBadCrc);
    // The simulator's way back: the CRCs written anew make it valid again.
    PandarQT128::write_crcs(bad);
    CHECK(PandarQT128::validate(bad) == RejectReason::kNone);
  }
  // Outside every CRC: the FS version byte (its CRC starts after it, as found on the capture)
  // and the signature.
  for (const std::size_t at : {1044u, 1095u, 1126u}) {
    std::vector<std::uint8_t> bad = packet;
    bad[at] ^= 0xFF;
    INFO("byte " << at);
    CHECK(PandarQT128::validate(bad) == RejectReason::kNone);
  }
}

TEST_CASE("validation's neighbours on real packets: length, start, header, azimuth, mode",
          "[sensors][real]") {
  // `modes`: the return-mode bytes the model sends, by its manual (MAN-64 §4.2.2, MAN-XT16
  // §3.1.2) and nebula's decoder for the QT128.
  const auto check_model = [&]<class M>(std::type_identity<M>, const char* file,
                                        const std::set<int>& modes) {
    const auto path = test::real_capture(file);
    if (!path) return;
    const std::vector<std::uint8_t> packet = test::capture_payloads(*path).at(0);
    INFO(display_name(M::kId));
    // Rewrites what a CRC covers, so the checks after it are reached (QT128 only).
    const auto sealed = [](std::vector<std::uint8_t> bytes) {
      if constexpr (std::is_same_v<M, PandarQT128>) PandarQT128::write_crcs(bytes);
      return bytes;
    };
    // Lengths around the packet's, and down to nothing. The Pandar64's 1194 is its length
    // without the UDP sequence: valid, and then without one.
    for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{11}, packet.size() - 4,
                                packet.size() - 1, packet.size() + 1, packet.size() + 4}) {
      std::vector<std::uint8_t> bytes(packet.begin(), packet.begin() + std::min(n, packet.size()));
      bytes.resize(n, 0);
      INFO(n << " bytes");
      if (std::is_same_v<M, Pandar64> && n == 1194) {
        CHECK(M::validate(bytes) == RejectReason::kNone);
        CHECK(detect_model(bytes).model == M::kId);
        CHECK_FALSE(M::sequence(bytes));
        continue;
      }
      CHECK(M::validate(bytes) == RejectReason::kBadLength);
      CHECK(detect_model(bytes).kind != DetectionKind::kKnown);
    }
    // The start bytes.
    for (const std::size_t at : {0u, 1u}) {
      std::vector<std::uint8_t> bytes = packet;
      bytes[at] ^= 0x10;
      CHECK(M::validate(bytes) == RejectReason::kBadMarker);
    }
    // The header's identity: protocol version (none for the 64), laser count, block count.
    const std::vector<std::size_t> identity = std::is_same_v<M, Pandar64>
                                                  ? std::vector<std::size_t>{2, 3}
                                                  : std::vector<std::size_t>{2, 3, 6, 7};
    for (const std::size_t at : identity) {
      std::vector<std::uint8_t> bytes = packet;
      bytes[at] ^= 0x01;
      INFO("header byte " << at);
      CHECK(M::validate(bytes) == RejectReason::kWrongModel);
    }
    // Each block's azimuth: 35999 is accepted, 36000 and 65535 are not.
    for (int b = 0; b < M::kBlocks; ++b) {
      const std::size_t at = static_cast<std::size_t>(M::block(packet, b) - packet.data());
      for (const int azimuth : {35999, 36000, 65535}) {
        std::vector<std::uint8_t> bytes = packet;
        bytes[at] = static_cast<std::uint8_t>(azimuth);
        bytes[at + 1] = static_cast<std::uint8_t>(azimuth >> 8);
        INFO("block " << b << " azimuth " << azimuth);
        CHECK(M::validate(sealed(bytes)) ==
              (azimuth < 36000 ? RejectReason::kNone : RejectReason::kBadAzimuth));
      }
    }
    // Every return-mode byte: accepted exactly when the model sends that mode.
    std::size_t mode_at = 0;
    if constexpr (std::is_same_v<M, PandarQT128>) {
      mode_at = PandarQT128::layout(packet).tail_offset + PandarQT128::kReturnModeInTail;
    } else {
      mode_at = M::kReturnModeOffset;
    }
    for (int mode = 0; mode < 256; ++mode) {
      std::vector<std::uint8_t> bytes = packet;
      bytes[mode_at] = static_cast<std::uint8_t>(mode);
      const bool sent = modes.count(mode) == 1;
      INFO("mode " << mode);
      CHECK(M::validate(sealed(bytes)) ==
            (sent ? RejectReason::kNone : RejectReason::kBadReturnMode));
    }
  };
  // Single first 0x33, strongest 0x37, last 0x38; dual last + strongest 0x39, first + last 0x3B,
  // first + strongest 0x3C.
  check_model(std::type_identity<Pandar64>{}, "pandar64_nebula_dual_1198B.pcap",
              {0x37, 0x38, 0x39});
  check_model(std::type_identity<PandarXT32>{}, "pandarxt32_nebula_dual_1080B.pcap",
              {0x33, 0x37, 0x38, 0x39, 0x3B, 0x3C});
  check_model(std::type_identity<PandarQT128>{}, "pandarqt128_nebula_laststrongest_1127B.pcap",
              {0x33, 0x37, 0x38, 0x39, 0x3B, 0x3C});
}

TEST_CASE("an XT16 packet is the XT protocol with the header's 16 channels", "[sensors][real]") {
  // No XT16 capture is in ../shared/captures/ (nebula's XT16 test data is a bag only), so the
  // XT16 packet is the XT32 capture's first packet cut to its first 16 channels, the header's
  // laser count set to 16: the layout the header's count gives.
  const auto path = test::real_capture("pandarxt32_nebula_dual_1080B.pcap");
  if (!path) return;
  const std::vector<std::uint8_t> xt32 = test::capture_payloads(*path).at(0);
  std::vector<std::uint8_t> xt16(xt32.begin(), xt32.begin() + PandarXT32::kHeaderBytes);
  xt16[PandarXT16::kLaserCountOffset] = 16;
  for (int b = 0; b < PandarXT32::kBlocks; ++b) {
    const std::uint8_t* block = PandarXT32::block(xt32, b);
    xt16.insert(xt16.end(), block, block + PandarXT16::kBlockBytes);
  }
  xt16.insert(xt16.end(), xt32.begin() + PandarXT32::kTailOffset, xt32.end());
  REQUIRE(xt16.size() == PandarXT16::kMaxDatagramBytes);

  REQUIRE(PandarXT16::validate(xt16) == RejectReason::kNone);
  CHECK(detect_model(xt16).kind == DetectionKind::kKnown);
  CHECK(detect_model(xt16).model == SensorModelId::kPandarXT16);
  for (int b = 0; b < PandarXT16::kBlocks; ++b) {
    CHECK(PandarXT16::azimuth_cdeg(xt16, b) == PandarXT32::azimuth_cdeg(xt32, b));
    for (int c = 0; c < PandarXT16::kChannels; ++c) {
      REQUIRE(PandarXT16::distance_raw(xt16, b, c) == PandarXT32::distance_raw(xt32, b, c));
      REQUIRE(PandarXT16::reflectivity(xt16, b, c) == PandarXT32::reflectivity(xt32, b, c));
      REQUIRE(PandarXT16::confidence(xt16, b, c) == PandarXT32::confidence(xt32, b, c));
    }
  }
  CHECK(PandarXT16::return_mode(xt16) == PandarXT32::return_mode(xt32));
  CHECK(PandarXT16::motor_rpm(xt16) == PandarXT32::motor_rpm(xt32));
  CHECK(PandarXT16::timestamp_us(xt16) == PandarXT32::timestamp_us(xt32));
  CHECK(PandarXT16::utc(xt16) == PandarXT32::utc(xt32));
  CHECK(PandarXT16::sequence(xt16) == PandarXT32::sequence(xt32));
  CHECK(PandarXT16::factory(xt16) == PandarXT32::factory(xt32));

  // Each model refuses the other's header; the count is the header's, not the length's.
  CHECK(PandarXT32::validate(xt16) == RejectReason::kWrongModel);
  CHECK(PandarXT16::validate(xt32) == RejectReason::kWrongModel);
  std::vector<std::uint8_t> xt16_header_xt32_length = xt32;
  xt16_header_xt32_length[PandarXT16::kLaserCountOffset] = 16;
  CHECK(PandarXT16::validate(xt16_header_xt32_length) == RejectReason::kBadLength);
  CHECK(identify_model(xt16_header_xt32_length).model == SensorModelId::kPandarXT16);
  CHECK(detect_model(xt16_header_xt32_length).kind == DetectionKind::kUnknown);
  CHECK(detect_model(xt16_header_xt32_length).reject == RejectReason::kBadLength);
}

TEST_CASE("detection names the Hesai models it does not decode, and knows no others",
          "[sensors][real]") {
  const auto path = test::real_capture("pandarxt32_nebula_dual_1080B.pcap");
  if (!path) return;
  const std::vector<std::uint8_t> packet = test::capture_payloads(*path).at(0);
  // A pre-header's major, minor, laser count and block count (bytes 2, 3, 6, 7) on the XT32's
  // bytes, and what detection says of them.
  struct Case {
    std::array<std::uint8_t, 4> id;
    DetectionKind kind;
    std::string_view name;
  };
  const std::vector<Case> cases = {
      {{6, 1, 32, 8}, DetectionKind::kKnown, ""},
      {{6, 1, 32, 6}, DetectionKind::kUnsupported, "XT32M"},
      {{6, 1, 64, 8}, DetectionKind::kUnknown, ""},
      {{6, 1, 16, 6}, DetectionKind::kUnknown, ""},
      {{6, 2, 32, 8}, DetectionKind::kUnknown, ""},
      {{3, 1, 64, 4}, DetectionKind::kUnsupported, "QT64"},
      {{3, 2, 64, 2}, DetectionKind::kUnknown, ""},
      {{4, 1, 128, 2}, DetectionKind::kUnsupported, "AT128"},
      {{4, 3, 128, 2}, DetectionKind::kUnsupported, "AT128"},
      {{4, 2, 128, 2}, DetectionKind::kUnknown, ""},
      {{1, 4, 128, 2}, DetectionKind::kUnsupported, "OT128/Pandar128E3X/E4X"},
      {{1, 8, 16, 1}, DetectionKind::kUnsupported, "JT16"},
      {{7, 2, 0, 1}, DetectionKind::kUnsupported, "FT120"},
      {{0, 0, 0, 0}, DetectionKind::kUnknown, ""},
      {{0x40, 0x06, 32, 8}, DetectionKind::kUnknown, ""},  // a 64's identity at another length
  };
  for (const Case& k : cases) {
    std::vector<std::uint8_t> bytes = packet;
    bytes[2] = k.id[0];
    bytes[3] = k.id[1];
    bytes[6] = k.id[2];
    bytes[7] = k.id[3];
    INFO(int{k.id[0]} << "." << int{k.id[1]} << " " << int{k.id[2]} << " lasers " << int{k.id[3]}
                      << " blocks");
    const DetectedModel found = detect_model(bytes);
    CHECK(found.kind == k.kind);
    CHECK(found.unsupported_name == k.name);
    CHECK(found.reject == RejectReason::kNone);
  }
  CHECK(detect_model(packet).model == SensorModelId::kPandarXT32);

  // By length: the Pandar20's, and the lengths of the 40P and 64 without their start bytes.
  std::vector<std::uint8_t> pandar20 = packet;
  pandar20.resize(1388, 0);
  CHECK(detect_model(pandar20).kind == DetectionKind::kUnsupported);
  CHECK(detect_model(pandar20).unsupported_name == "Pandar20");
  for (const std::size_t n : {std::size_t{1262}, std::size_t{1266}, std::size_t{1194}}) {
    std::vector<std::uint8_t> bytes = packet;
    bytes.resize(n, 0);
    bytes[0] = 0xAA;
    INFO(n << " bytes starting AA");
    CHECK(detect_model(bytes).kind == DetectionKind::kUnknown);
  }
  // Nothing reads past a short payload.
  for (std::size_t n = 0; n < 12; ++n) {
    const std::vector<std::uint8_t> bytes(packet.begin(), packet.begin() + n);
    INFO(n << " bytes");
    CHECK(detect_model(bytes).kind != DetectionKind::kKnown);
  }
}

TEST_CASE("a real 1266-byte Pandar40P packet is detected as one, with its UDP sequence",
          "[sensors][real]") {
  const auto path = test::real_capture("velocityreport_pandar40p_single_packet_1266B.pcapng");
  if (!path) return;
  const Payloads payloads = test::capture_payloads(*path);
  REQUIRE(payloads.size() == 1);
  const std::span<const std::uint8_t> p = payloads[0];
  REQUIRE(p.size() == 1266);
  CHECK(Pandar40P::validate(p) == RejectReason::kNone);
  CHECK(detect_model(p).kind == DetectionKind::kKnown);
  CHECK(detect_model(p).model == SensorModelId::kPandar40P);
  CHECK(Pandar40P::sequence(p).has_value());
  CHECK(Pandar40P::return_mode(p) == ReturnMode::kLast);
  CHECK(returns_per_firing(Pandar40P::return_mode(p)) == 1);
  // A Pandar64 validating it says whose it is not.
  CHECK(Pandar64::validate(p) == RejectReason::kBadMarker);
}

TEST_CASE("model names: display, lower case, parsed in any case, auto is not a model",
          "[sensors]") {
  const std::map<SensorModelId, std::pair<std::string, std::string>> names = {
      {SensorModelId::kPandar40P, {"Pandar40P", "pandar40p"}},
      {SensorModelId::kPandar64, {"Pandar64", "pandar64"}},
      {SensorModelId::kPandarXT32, {"PandarXT32", "pandarxt32"}},
      {SensorModelId::kPandarXT16, {"PandarXT16", "pandarxt16"}},
      {SensorModelId::kPandarQT128, {"PandarQT128", "pandarqt128"}}};
  REQUIRE(names.size() == kSensorModelIds.size());
  for (const SensorModelId id : kSensorModelIds) {
    const auto& [display, lower] = names.at(id);
    CHECK(display_name(id) == display);
    CHECK(lower_case_name(id) == lower);
    std::string upper = lower;
    std::transform(upper.begin(), upper.end(), upper.begin(), [](char ch) {
      return static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    });
    for (const std::string& name : {display, lower, upper}) {
      INFO(name);
      CHECK(parse_sensor_model(name) == id);
    }
  }
  for (const char* name : {"auto", "", "pandar40", "pandar40p ", "xt32", "PandarXT", "Pandar128"}) {
    INFO("'" << name << "'");
    CHECK_FALSE(parse_sensor_model(name));
  }
}

TEST_CASE("each capture's calibration file loads as its model's, and only as its model's",
          "[sensors][real]") {
  struct File {
    const char* name;
    SensorModelId model;
    // How far the unit's file lies from the model's nominal table (most per channel, degrees):
    // wide enough for this unit, narrower than a table shifted by one channel.
    double elevation_tolerance_deg;
    double azimuth_tolerance_deg;
  };
  const File files[] = {
      {"nebula_Pandar40P_calibration.csv", SensorModelId::kPandar40P, 0.25, 0},
      {"nebula_Pandar64_calibration.csv", SensorModelId::kPandar64, 0.15, 0},
      {"nebula_PandarXT32_calibration.csv", SensorModelId::kPandarXT32, 0.1, 0.15},
      // The nominal table is the file Hesai ships (pandar_qt128.hpp).
      {"nebula_PandarQT128_calibration.csv", SensorModelId::kPandarQT128, 0, 0}};
  for (const File& f : files) {
    const auto path = test::real_capture(f.name);
    if (!path) continue;
    INFO(f.name);
    std::ifstream in(*path, std::ios::binary);
    REQUIRE(in);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int channels = channel_count(f.model);
    const Calibration c = Calibration::parse(text, f.name, f.model);
    CHECK(c.channel_count == channels);
    CHECK(c.source == f.name);
    const Calibration nominal = Calibration::nominal(f.model);
    CHECK(nominal.channel_count == channels);
    for (int ch = 0; ch < kMaxChannels; ++ch) {
      const auto i = static_cast<std::size_t>(ch);
      INFO("channel " << ch + 1);
      if (ch < channels) {
        CHECK(std::abs(c.elevation_deg[i] - nominal.elevation_deg[i]) <= f.elevation_tolerance_deg);
        CHECK(std::abs(c.azimuth_offset_deg[i] - nominal.azimuth_offset_deg[i]) <=
              f.azimuth_tolerance_deg);
      } else {  // the rows past the model's stay 0
        CHECK(c.elevation_deg[i] == 0);
        CHECK(c.azimuth_offset_deg[i] == 0);
        CHECK(nominal.elevation_deg[i] == 0);
      }
    }
    // The file's first and last rows, as the file has them.
    const auto last = static_cast<std::size_t>(channels - 1);
    const std::size_t first_row = text.find('\n') + 1;
    CHECK(text.substr(first_row, text.find('\n', first_row) - first_row) ==
          fmt::format("1,{},{}", c.elevation_deg[0], c.azimuth_offset_deg[0]));
    std::string tail = text.substr(0, text.find_last_not_of("\r\n") + 1);
    tail = tail.substr(tail.rfind('\n') + 1);
    CHECK(tail ==
          fmt::format("{},{},{}", channels, c.elevation_deg[last], c.azimuth_offset_deg[last]));
    // Every other model refuses it at a place in the file, naming the count it expected.
    for (const SensorModelId other : kSensorModelIds) {
      if (other == f.model) continue;
      INFO("as " << display_name(other));
      try {
        (void)Calibration::parse(text, f.name, other);
        FAIL("accepted");
      } catch (const CalibrationError& e) {
        const std::string message = e.what();
        INFO(message);
        CHECK(message.rfind(std::string(f.name) + ":", 0) == 0);
        CHECK(message.find(fmt::format("expected {} channels ({})", channel_count(other),
                                       display_name(other))) != std::string::npos);
      }
    }
  }
}

TEST_CASE(
    "firing times: a firing's blocks share its time, firings a period apart, all inside "
    "the packet's period",
    "[sensors]") {
  const auto check = [&]<class M>(std::type_identity<M>, std::uint8_t mode_flag) {
    for (const int returns : {1, 2}) {
      INFO(display_name(M::kId) << ", " << returns << " returns, mode flag " << int{mode_flag});
      const auto offset = [&](int b, int c) {
        if constexpr (std::is_same_v<M, PandarQT128>) {
          return PandarQT128::firing_offset_ns(b, c, returns, mode_flag);
        } else {
          return M::firing_offset_ns(b, c, returns);
        }
      };
      std::int64_t earliest = offset(0, 0), latest = earliest;
      for (int b = 0; b < M::kBlocks; ++b) {
        for (int c = 0; c < M::kChannels; ++c) {
          earliest = std::min(earliest, offset(b, c));
          latest = std::max(latest, offset(b, c));
          if (b % returns != 0) {  // a firing's later echoes: its first block's time
            REQUIRE(offset(b, c) == offset(b - b % returns, c));
          } else if (b > 0 && !std::is_same_v<M, PandarQT128>) {  // one sequence: a period on
            REQUIRE(offset(b, c) - offset(b - returns, c) == M::kFiringPeriodNs);
          }
        }
      }
      CHECK(latest - earliest < M::packet_period_ns(returns));
    }
  };
  check(std::type_identity<Pandar40P>{}, 0);
  check(std::type_identity<Pandar64>{}, 0);
  check(std::type_identity<PandarXT32>{}, 0);
  check(std::type_identity<PandarXT16>{}, 0);
  check(std::type_identity<PandarQT128>{}, 0);
  check(std::type_identity<PandarQT128>{}, 1);
  // The QT128's two sequences: each fires channels 64-127 and one half of 0-63; a single-return
  // packet's two blocks are two firings a period apart, one of each sequence.
  for (int c = 0; c < PandarQT128::kChannels; ++c) {
    INFO("channel " << c);
    CHECK(PandarQT128::fires(1, c) == (c >= 32));
    CHECK(PandarQT128::fires(2, c) == (c < 32 || c >= 64));
  }
  for (const std::uint8_t flag : {std::uint8_t{0}, std::uint8_t{1}}) {
    CHECK(PandarQT128::firing_sequence(flag, 0, 1) != PandarQT128::firing_sequence(flag, 1, 1));
    CHECK(PandarQT128::firing_offset_ns(0, 0, 1, flag) >= PandarQT128::kFirstFiringNs);
    CHECK(PandarQT128::firing_offset_ns(1, 64, 1, flag) >=
          PandarQT128::kFirstFiringNs + PandarQT128::kFiringPeriodNs);
  }
}
