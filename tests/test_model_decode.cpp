// The Pandar64, PandarXT32 and PandarQT128 captures (tier4/nebula's test data) decoded end to end
// by their models' stream decoders, and the rules a stream of another model meets. The checks
// are physical and by accounting: every channel slot is a point or a counted filter, whole
// revolutions are cut whole at the cut angle, each point lies within its model's range and
// channels, points of one channel line up with their calibration's elevation. The point-for-point
// comparison with nebula's decode path is test_model_reference (the daemon's frames against the
// independent reference decoder in tests/reference/).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <map>
#include <vector>

#include "core/decode/any_stream_decoder.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/model_access.hpp"
#include "core/sensors/model_detection.hpp"
#include "core/sensors/sensor_models.hpp"
#include "daemon/io/calibration_file.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace pandarcap::test;

namespace {

struct RealCapture {
  SensorModelId model;
  const char* capture;
  const char* calibration;
  double min_range_m, max_range_m;  // nebula's test settings (../shared/captures/README.md)
};

constexpr RealCapture kCaptures[] = {
    {SensorModelId::kPandar64, "pandar64_nebula_dual_1198B.pcap", "nebula_Pandar64_calibration.csv",
     0.3, 200},
    {SensorModelId::kPandarXT32, "pandarxt32_nebula_dual_1080B.pcap",
     "nebula_PandarXT32_calibration.csv", 0.05, 120},
    {SensorModelId::kPandarQT128, "pandarqt128_nebula_laststrongest_1127B.pcap",
     "nebula_PandarQT128_calibration.csv", 0.3, 300},
};

struct ModelDecoded {
  std::vector<FrameInfo> frames;
  std::vector<std::vector<Point>> points;
  StreamStats stats;
  AssemblerStats assembler;
};

ModelDecoded decode_payloads(const RealCapture& c,
                             const std::vector<std::vector<std::uint8_t>>& payloads,
                             const Calibration& calibration) {
  ModelDecoded out;
  FrameCollector sink(3, 300'000, [&](const Frame& f) {
    out.frames.push_back(f.info);
    out.points.emplace_back(f.points.begin(), f.points.begin() + f.info.points);
  });
  StreamDecoderConfig config;
  config.decoder.min_range_m = c.min_range_m;
  config.decoder.max_range_m = c.max_range_m;
  AnyStreamDecoder decoder(c.model, calibration, config, sink);
  for (const auto& p : payloads)
    decoder.process(p);
  decoder.flush();
  out.stats = decoder.stats();
  out.assembler = decoder.frames();
  return out;
}

}  // namespace

TEST_CASE("each new model's real capture decodes into whole revolutions, every slot accounted",
          "[sensors][decode]") {
  for (const RealCapture& c : kCaptures) {
    CAPTURE(c.capture);
    const auto capture = real_capture(c.capture);
    const auto csv = real_capture(c.calibration);
    if (!capture || !csv) continue;
    const auto payloads = capture_payloads(*capture);
    const Calibration calibration = load_calibration(csv->string(), c.model);
    REQUIRE(calibration.channel_count == channel_count(c.model));
    // The model is the packets' (detect_model), the one the replay would choose.
    for (const auto& p : payloads)
      REQUIRE(detect_model(p).model == c.model);

    const ModelDecoded d = decode_payloads(c, payloads, calibration);
    CHECK(d.stats.accepted == payloads.size());
    CHECK(d.stats.rejected() == 0);
    CHECK(d.stats.outliers == 0);
    CHECK(d.stats.stream_changes == 0);
    CHECK(d.stats.azimuth_gaps == 0);
    CHECK(d.assembler.discontinuities == 0);
    const std::uint64_t slots =
        with_model(c.model,
                   []<class M>(std::type_identity<M>) { return M::kBlocks * M::kChannels; }) *
        payloads.size();
    CHECK(d.stats.points + d.stats.filtered.total() == slots);
    std::uint64_t in_frames = 0;
    for (const FrameInfo& f : d.frames)
      in_frames += f.points;
    CHECK(in_frames + d.assembler.points_late + d.assembler.points_dropped_full +
              d.assembler.points_dropped_no_frame ==
          d.stats.points);

    // The captures hold 4 revolutions (the QT128's 2): the ones between two cuts are whole
    // (the QT128's one between its two cuts ends with the capture, a frame closed at the end).
    const double revolutions = c.model == SensorModelId::kPandarQT128 ? 2 : 4;
    const double per_revolution = static_cast<double>(payloads.size()) / revolutions;
    std::size_t whole = 0;
    for (std::size_t i = 0; i < d.frames.size(); ++i) {
      const FrameInfo& f = d.frames[i];
      if (f.partial) continue;
      ++whole;
      CHECK(std::abs(f.packets - per_revolution) <= 0.05 * per_revolution);
      CHECK(f.azimuth_span_cdeg > 35000);
      CHECK(std::abs(f.rpm - 600) < 10);
    }
    CHECK(whole >= (c.model == SensorModelId::kPandarQT128 ? 0u : 2u));

    // Every point: the model's channels, within the ranges, at its channel's elevation (z / r is
    // the sine of the calibration's elevation).
    std::size_t checked = 0;
    for (const auto& frame : d.points) {
      for (const Point& p : frame) {
        REQUIRE(p.channel < calibration.channel_count);
        const double r = std::sqrt(double{p.x} * p.x + double{p.y} * p.y + double{p.z} * p.z);
        REQUIRE(r >= c.min_range_m - 1e-3);
        REQUIRE(r <=
                std::min(c.max_range_m, c.model == SensorModelId::kPandarQT128 ? 50.0 : 200.0) +
                    1e-3);
        REQUIRE(std::abs(r - p.distance_m) < 1e-3 * std::max(1.0, r));
        const double elevation = std::asin(p.z / r) * 180 / 3.14159265358979;
        REQUIRE(std::abs(elevation - calibration.elevation_deg[p.channel]) < 0.01);
        ++checked;
      }
    }
    CHECK(checked > 50'000);
  }
}

TEST_CASE("dual-return captures keep both echoes only where they differ by the threshold",
          "[sensors][decode]") {
  for (const RealCapture& c : kCaptures) {
    CAPTURE(c.capture);
    const auto capture = real_capture(c.capture);
    const auto csv = real_capture(c.calibration);
    if (!capture || !csv) continue;
    const auto payloads = capture_payloads(*capture);
    const ModelDecoded d = decode_payloads(c, payloads, load_calibration(csv->string(), c.model));
    // Last + strongest: a channel's two points of one firing are at least 0.1 m apart, and the
    // merged ones are labelled last_strongest.
    std::map<std::pair<std::int64_t, int>, std::vector<const Point*>> by_firing;
    for (const Point& p : d.points.back())
      by_firing[{p.timestamp_ns / 1000, p.channel}].push_back(&p);
    std::size_t pairs = 0, merged = 0;
    for (const auto& [key, points] : by_firing) {
      if (points.size() == 2) {
        ++pairs;
        CHECK(std::abs(points[0]->distance_m - points[1]->distance_m) >= 0.1 - 1e-4);
      }
      for (const Point* p : points)
        merged += p->return_type == ReturnType::kLastStrongest;
    }
    CHECK(d.stats.filtered[FilterReason::kDualDuplicate] +
              d.stats.filtered[FilterReason::kDualTooClose] >
          0);
    CHECK(merged > 0);
    CHECK(pairs > 0);
  }
}

TEST_CASE("a stream decoder counts another model's packets as wrong_model, unsupported ones apart",
          "[sensors][decode]") {
  const auto p64 = real_capture("pandar64_nebula_dual_1198B.pcap");
  const auto p40 = real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  const auto xt = real_capture("pandarxt32_nebula_dual_1080B.pcap");
  if (!p64 || !p40 || !xt) return;
  const auto a = capture_payloads(*p64);
  const auto b = capture_payloads(*p40);
  const auto x = capture_payloads(*xt);
  FrameCollector sink(3, 300'000, [](const Frame&) {});
  for (const SensorModelId model : {SensorModelId::kPandar40P, SensorModelId::kPandar64}) {
    CAPTURE(display_name(model));
    AnyStreamDecoder decoder(model, Calibration::nominal(model), {}, sink);
    const auto& own = model == SensorModelId::kPandar40P ? b : a;
    const auto& other = model == SensorModelId::kPandar40P ? a : b;
    for (std::size_t i = 0; i < 100; ++i) {
      decoder.process(own[i]);
      decoder.process(other[i]);
      decoder.process(x[i]);
    }
    // An AT128's header (protocol 4.1) on an XT's bytes: named, not decoded.
    std::vector<std::uint8_t> at128 = x[0];
    at128[2] = 4;
    at128[3] = 1;
    decoder.process(at128);
    CHECK(decoder.stats().accepted == 100);
    CHECK(decoder.stats().rejects_for(RejectReason::kWrongModel) == 200);
    CHECK(decoder.stats().rejects_for(RejectReason::kUnsupportedModel) == 1);
    CHECK(decoder.stats().rejects_for(RejectReason::kBadLength) == 0);
  }
}

TEST_CASE("a glitched azimuth in a Pandar64 or QT128 stream costs only its packet",
          "[sensors][decode]") {
  for (const RealCapture& c : kCaptures) {
    CAPTURE(c.capture);
    const auto capture = real_capture(c.capture);
    const auto csv = real_capture(c.calibration);
    if (!capture || !csv) continue;
    auto payloads = capture_payloads(*capture);
    const Calibration calibration = load_calibration(csv->string(), c.model);
    const ModelDecoded clean = decode_payloads(c, payloads, calibration);
    // Shift every block azimuth of packets 700, 701 by 30°: the outlier rule repairs them from
    // their time (the model's block offsets in model_access.hpp), the frames stay whole.
    for (const std::size_t k : {std::size_t{700}, std::size_t{701}}) {
      auto& p = payloads[k];
      with_model(c.model, [&]<class M>(std::type_identity<M>) {
        for (int b = 0; b < M::kBlocks; ++b) {
          const std::size_t at = block_azimuth_offset<M>(p, b);
          const int az = (load_u16_le(p.data() + at) + 3000) % 36000;
          p[at] = static_cast<std::uint8_t>(az);
          p[at + 1] = static_cast<std::uint8_t>(az >> 8);
        }
        if constexpr (std::same_as<M, PandarQT128>) PandarQT128::write_crcs(p);
      });
    }
    const ModelDecoded d = decode_payloads(c, payloads, calibration);
    CHECK(d.stats.outliers == 2);
    CHECK(d.stats.stream_changes == 0);
    CHECK(d.assembler.frames_complete == clean.assembler.frames_complete);
    CHECK(d.stats.points == clean.stats.points);
  }
}
