// Malformed packets in a valid stream, through the whole decode path (StreamDecoder), with every
// decoder this machine runs: each malformed payload raises exactly its own reject counter and
// nothing else, and the valid packets around it decode exactly as they do without it: the same
// frames, point for point, and the same counts.
#include <catch2/catch.hpp>
#include <cstring>
#include <string>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/packet.hpp"
#include "core/sim/synthetic_sensor.hpp"

using namespace pandarcap;

namespace {

using Bytes = std::vector<std::uint8_t>;

struct Malformed {
  std::string name;
  Bytes bytes;
  RejectReason reason;
};

// Every kind of bad payload the daemon can be sent, built from a valid one.
std::vector<Malformed> malformed_from(const Bytes& good) {
  std::vector<Malformed> cases;
  for (std::size_t size : {0, 1, 1261, 1263, 1265, 1267, 65507}) {
    Bytes bytes(size, 0xA5);
    std::copy_n(good.begin(), std::min(size, good.size()), bytes.begin());
    cases.push_back({"size " + std::to_string(size), bytes, RejectReason::kBadLength});
  }
  cases.push_back(
      {"truncated to 700", Bytes(good.begin(), good.begin() + 700), RejectReason::kBadLength});
  for (int b = 0; b < kBlocks; ++b) {
    Bytes marker = good;
    marker[kBlockBytes * b + 1] = 0xEF;
    cases.push_back({"bad marker in block " + std::to_string(b), marker, RejectReason::kBadMarker});
    for (std::uint16_t azimuth : {std::uint16_t{36000}, std::uint16_t{65535}}) {
      Bytes bytes = good;
      bytes[kBlockBytes * b + 2] = static_cast<std::uint8_t>(azimuth);
      bytes[kBlockBytes * b + 3] = static_cast<std::uint8_t>(azimuth >> 8);
      cases.push_back({"azimuth " + std::to_string(azimuth) + " in block " + std::to_string(b),
                       bytes, RejectReason::kBadAzimuth});
    }
  }
  for (int mode : {0x00, 0x36, 0x3A, 0xFF}) {
    Bytes bytes = good;
    bytes[kBodyBytes + 14] = static_cast<std::uint8_t>(mode);  // the tail's return mode byte
    cases.push_back({"return mode " + std::to_string(mode), bytes, RejectReason::kBadReturnMode});
  }
  // Another model's header: a Pandar64's (by its length and counts), an XT32's (protocol 6.1,
  // 32 lasers, 8 blocks) are wrong_model; an AT128's (protocol 4.1) is a model pandarcap does not
  // decode. None is ever read as the 40P's bytes.
  Bytes p64(1194, 0x11);
  p64[0] = 0xEE, p64[1] = 0xFF, p64[2] = 64, p64[3] = 6;
  cases.push_back({"a Pandar64 header", p64, RejectReason::kWrongModel});
  Bytes xt32(1080, 0x22);
  xt32[0] = 0xEE, xt32[1] = 0xFF, xt32[2] = 6, xt32[3] = 1, xt32[6] = 32, xt32[7] = 8;
  cases.push_back({"a PandarXT32 header", xt32, RejectReason::kWrongModel});
  Bytes at128(1118, 0x33);
  at128[0] = 0xEE, at128[1] = 0xFF, at128[2] = 4, at128[3] = 1;
  cases.push_back({"an AT128 header", at128, RejectReason::kUnsupportedModel});
  cases.push_back({"all zeros", Bytes(kPacketBytes, 0x00), RejectReason::kBadMarker});
  cases.push_back({"all 0xFF", Bytes(kPacketBytes, 0xFF), RejectReason::kBadMarker});
  cases.push_back(
      {"all 0xFF with sequence", Bytes(kPacketWithSequenceBytes, 0xFF), RejectReason::kBadMarker});
  return cases;
}

// What a run produced: every frame's points (bytes) and info, and the stream counts.
struct MalformedRun {
  std::vector<std::vector<Point>> frames;
  std::vector<FrameInfo> infos;
  StreamStats stats;
};

class Decoding {
 public:
  explicit Decoding(DecoderTarget target)
      : collector_(4, 200'000,
                   [this](const Frame& f) {
                     run_.frames.emplace_back(f.used().begin(), f.used().end());
                     run_.infos.push_back(f.info);
                   }),
        decoder_(Calibration::nominal(), config(target), collector_) {}
  RejectReason process(const Bytes& bytes) { return decoder_.process(bytes); }
  const StreamStats& stats() const { return decoder_.stats(); }
  MalformedRun finish() {
    decoder_.flush();
    run_.stats = decoder_.stats();
    return run_;
  }

 private:
  static StreamDecoderConfig config(DecoderTarget target) {
    StreamDecoderConfig c;
    c.decoder_target = target;
    return c;
  }
  MalformedRun run_;
  FrameCollector collector_;
  StreamDecoder decoder_;
};

bool same_points(const std::vector<Point>& a, const std::vector<Point>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Point)) == 0;
}

// The counts a rejected packet must leave alone.
void check_untouched(const StreamStats& before, const StreamStats& after) {
  CHECK(after.accepted == before.accepted);
  CHECK(after.points == before.points);
  CHECK(after.filtered.by_reason == before.filtered.by_reason);
  CHECK(after.bad_date == before.bad_date);
  CHECK(after.static_timestamps == before.static_timestamps);
  CHECK(after.azimuth_gaps == before.azimuth_gaps);
  CHECK(after.sequence_packets == before.sequence_packets);
}

}  // namespace

TEST_CASE(
    "malformed packets raise exactly their own reject counter - the stream decodes as without "
    "them",
    "[malformed][stream]") {
  SyntheticSensorConfig sensor_config;
  sensor_config.udp_sequence = GENERATE(false, true);
  SyntheticSensor sensor(sensor_config);
  std::vector<Bytes> stream;
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (int i = 0; i < 1200; ++i) {  // a little over three revolutions at 600 RPM, dual return
    const std::size_t size = sensor.next(buffer);
    stream.emplace_back(buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(size));
  }
  const std::vector<Malformed> cases = malformed_from(stream[0]);

  for (const DecoderTarget target : supported_decoder_targets()) {
    INFO("decoder " << to_string(target) << ", UDP sequence " << sensor_config.udp_sequence);
    Decoding clean(target);
    for (const Bytes& packet : stream)
      REQUIRE(clean.process(packet) == RejectReason::kNone);
    const MalformedRun expected = clean.finish();
    REQUIRE(expected.frames.size() >= 3);

    Decoding mixed(target);
    std::array<std::uint64_t, kRejectReasonCount> injected{};
    for (std::size_t i = 0; i < stream.size(); ++i) {
      REQUIRE(mixed.process(stream[i]) == RejectReason::kNone);
      const Malformed& bad = cases[i % cases.size()];
      INFO(bad.name);
      const StreamStats before = mixed.stats();
      CHECK(mixed.process(bad.bytes) == bad.reason);
      ++injected[static_cast<std::size_t>(bad.reason)];
      const StreamStats& after = mixed.stats();
      CHECK(after.packets == before.packets + 1);
      for (std::size_t r = 0; r < kRejectReasonCount; ++r) {
        CHECK(after.rejects[r] == before.rejects[r] + (r == static_cast<std::size_t>(bad.reason)));
      }
      check_untouched(before, after);
    }
    const MalformedRun got = mixed.finish();

    CHECK(got.stats.accepted == expected.stats.accepted);
    for (std::size_t r = 1; r < kRejectReasonCount; ++r) {  // 0 is kNone, not a reject
      CHECK(got.stats.rejects[r] == injected[r]);
      // Every reason a Pandar40P stream can meet is injected. bad_crc is the QT128's own (its
      // packet in a 40P stream is wrong_model).
      const auto reason = static_cast<RejectReason>(r);
      if (reason != RejectReason::kBadCrc) {
        CHECK(injected[r] > 0);
      }
    }
    CHECK(got.stats.rejected() == stream.size());
    CHECK(got.stats.packets == expected.stats.packets + stream.size());
    CHECK(got.stats.points == expected.stats.points);
    CHECK(got.stats.filtered.by_reason == expected.stats.filtered.by_reason);
    REQUIRE(got.frames.size() == expected.frames.size());
    for (std::size_t f = 0; f < got.frames.size(); ++f) {
      INFO("frame " << f);
      CHECK(same_points(got.frames[f], expected.frames[f]));
      CHECK(got.infos[f].sequence == expected.infos[f].sequence);
    }
  }
}

TEST_CASE("a date out of range keeps the packet, counts bad_date, and the next one is as before",
          "[malformed][stream]") {
  SyntheticSensor sensor({});
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  std::vector<Bytes> stream;
  for (int i = 0; i < 3; ++i) {
    const std::size_t size = sensor.next(buffer);
    stream.emplace_back(buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(size));
  }
  // Tail bytes 16..21: year since 2000, month, day, hour, minute, second.
  const std::size_t date = kBodyBytes + 16;
  for (const auto& [field, value] : std::vector<std::pair<std::size_t, std::uint8_t>>{
           {1, 0}, {1, 13}, {2, 0}, {2, 32}, {3, 24}, {4, 60}, {5, 61}, {1, 0xFF}}) {
    INFO("date byte " << field << " = " << int{value});
    Decoding clean(DecoderTarget::kScalar), mixed(DecoderTarget::kScalar);
    Bytes broken = stream[1];
    broken[date + field] = value;
    for (const Bytes* p : {&stream[0], &stream[1], &stream[2]})
      clean.process(*p);
    for (const Bytes* p : {&stream[0], &broken, &stream[2]})
      CHECK(mixed.process(*p) == RejectReason::kNone);
    CHECK(mixed.stats().bad_date == 1);
    CHECK(mixed.stats().rejected() == 0);
    // The packet after it has its absolute time again, as in the clean stream.
    CHECK(mixed.stats().last_t0_ns == clean.stats().last_t0_ns);
  }
}
