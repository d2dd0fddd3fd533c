#include "support/retimed_capture.hpp"

#include <catch2/catch.hpp>
#include <cstring>

#include "core/decode/packet_time.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "support/test_support.hpp"

namespace pandarcap::test {

namespace {

constexpr std::size_t kTail = kBodyBytes;  // the tail's offset in a packet

void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}

void put_u32(std::uint8_t* p, std::uint32_t v) {
  put_u16(p, static_cast<std::uint16_t>(v));
  put_u16(p + 2, static_cast<std::uint16_t>(v >> 16));
}

void put_date(std::span<std::uint8_t> packet, const TailDateTime& utc) {
  std::uint8_t* t = packet.data() + kTail + 16;
  t[0] = utc.year_since_2000;
  t[1] = utc.month;
  t[2] = utc.day;
  t[3] = utc.hour;
  t[4] = utc.minute;
  t[5] = utc.second;
}

}  // namespace

std::optional<RetimedCapture> RetimedCapture::load(ReturnMode mode) {
  const auto path = real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!path) return std::nullopt;
  std::vector<std::array<std::uint8_t, kPacketBytes>> dual;
  CaptureReader reader(path->string());
  CaptureRecord record;
  while (reader.next(record) == CaptureStatus::kRecord) {
    REQUIRE(record.payload.size() == kPacketBytes);
    std::array<std::uint8_t, kPacketBytes> body{};
    std::memcpy(body.data(), record.payload.data(), kPacketBytes);
    dual.push_back(body);
  }
  REQUIRE(dual.size() == 1439);
  RetimedCapture stream;
  stream.mode_ = mode;
  if (mode == ReturnMode::kDual) {
    stream.bodies_ = std::move(dual);
    stream.per_second_ = 3600;
  } else {
    // Two dual packets' last (even) or strongest (odd) blocks, in firing order: ten rounds.
    const int parity = mode == ReturnMode::kStrongest ? 1 : 0;
    for (std::size_t i = 0; i + 1 < dual.size(); i += 2) {
      std::array<std::uint8_t, kPacketBytes> body = dual[i];
      for (int b = 0; b < kBlocks; ++b) {
        const auto& from = dual[i + static_cast<std::size_t>(b / 5)];
        const int block = 2 * (b % 5) + parity;
        std::memcpy(body.data() + kBlockBytes * b, from.data() + kBlockBytes * block, kBlockBytes);
      }
      body[kTail + 14] = static_cast<std::uint8_t>(mode);
      stream.bodies_.push_back(body);
    }
    stream.per_second_ = 1800;
    // 1439 dual packets make 719 single ones: the loop skips a dual packet where it joins, a
    // step of 2.85° where 2° is due. Each loop is turned back by the difference, so the stream
    // is a sensor's (the dual one keeps its own seam, 0.15° short: the capture's).
    const auto azimuth = [&](std::size_t i) {
      return static_cast<int>(load_u16_le(stream.bodies_[i].data() + 2));
    };
    const std::size_t last = stream.bodies_.size() - 1;
    const int seam = ((azimuth(0) - azimuth(last)) % 36000 + 36000) % 36000;
    const int usual = ((azimuth(last) - azimuth(last - 1)) % 36000 + 36000) % 36000;
    stream.seam_cdeg_ = seam - usual;
  }
  stream.period_ns_ = 1'000'000'000 / static_cast<std::int64_t>(stream.per_second_);
  return stream;
}

std::size_t RetimedCapture::packet(std::uint64_t k, std::span<std::uint8_t, kMaxPacketBytes> out,
                                   std::optional<std::uint32_t> sequence) const {
  std::memcpy(out.data(), bodies_[k % bodies_.size()].data(), kPacketBytes);
  const auto loops = static_cast<std::int64_t>(k / bodies_.size());
  if (seam_cdeg_ != 0 && loops > 0) {
    shift_azimuth(out.first(kPacketBytes), static_cast<int>(-loops * seam_cdeg_ % 36000));
  }
  set_time(out.first(kPacketBytes), time_ns(k));
  if (!sequence) return kPacketBytes;
  put_u32(out.data() + kPacketBytes, *sequence);
  return kPacketWithSequenceBytes;
}

void set_time(std::span<std::uint8_t> packet, std::int64_t unix_ns) {
  put_date(packet, tail_datetime_from_unix(unix_ns / 1'000'000'000));
  put_u32(packet.data() + kTail + 10, static_cast<std::uint32_t>(unix_ns % 1'000'000'000 / 1000));
}

void date_second_back(std::span<std::uint8_t> packet) {
  const PacketView view = PacketView::assume_valid(packet);
  PacketClock clock;
  const PacketTime time = clock.convert(view.utc(), view.timestamp_us());
  put_date(packet, tail_datetime_from_unix(time.t0_ns / 1'000'000'000 - 1));
}

void zero_time(std::span<std::uint8_t> packet) {
  put_date(packet, TailDateTime{});
  put_u32(packet.data() + kTail + 10, 0);
}

void garbage_time(std::span<std::uint8_t> packet, std::uint32_t seed) {
  // A month no calendar has, and microseconds past a second: a tail no clock wrote.
  put_date(packet, TailDateTime{static_cast<std::uint8_t>(seed), 13,
                                static_cast<std::uint8_t>(seed >> 8), 25, 61, 61});
  put_u32(packet.data() + kTail + 10, 1'000'001 + (seed % 1000));
}

void shift_azimuth(std::span<std::uint8_t> packet, int cdeg) {
  for (int b = 0; b < kBlocks; ++b) {
    std::uint8_t* p = packet.data() + kBlockBytes * b + 2;
    const int azimuth = load_u16_le(p);
    put_u16(p, static_cast<std::uint16_t>(((azimuth + cdeg) % 36000 + 36000) % 36000));
  }
}

void set_azimuth(std::span<std::uint8_t> packet, int cdeg) {
  for (int b = 0; b < kBlocks; ++b)
    put_u16(packet.data() + kBlockBytes * b + 2, static_cast<std::uint16_t>(cdeg));
}

void set_rpm(std::span<std::uint8_t> packet, std::uint16_t rpm) {
  put_u16(packet.data() + kTail + 8, rpm);
}

std::uint16_t first_azimuth(std::span<const std::uint8_t> packet) {
  return load_u16_le(packet.data() + 2);
}

}  // namespace pandarcap::test
