// The frame assembler against its header contract and spec §4.2 (NEB-style per-channel cut).
//
// Hand-made streams carry their ground truth: every point's unwrapped corrected azimuth U (0.01°,
// never wrapped, measured from the cut), so the frame a point must land in is floor(U / 36000),
// worked out without the assembler's own wrapping logic. Points are identified by an id stored in
// Point::x. (The end-to-end runs through the stream decoder are in test_stream_decoder.cpp.)
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "core/decode/calibration.hpp"
#include "core/decode/decoder.hpp"
#include "core/decode/frame_assembler.hpp"
#include "core/frames/frame.hpp"
#include "core/frames/pcd.hpp"
#include "core/sensors/timing.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

using test::floor_div;
using test::floor_mod;
using test::kCircle;

// Azimuth offset of each channel (0.01°) in the nominal calibration: -104, +313 or -521.
std::array<int, kChannels> nominal_offsets_cdeg() {
  const Calibration calibration = Calibration::nominal();
  std::array<int, kChannels> offsets{};
  for (int c = 0; c < kChannels; ++c)
    offsets[c] = static_cast<int>(std::lround(calibration.azimuth_offset_deg[c] * 100));
  return offsets;
}

// The bounds the decode path gives the assembler for the nominal calibration.
std::pair<int, int> nominal_bounds() {
  return ScalarDecoder(Calibration::nominal(), {}).relative_azimuth_bounds_cdeg();
}

FrameAssemblerConfig config_for(int cut_cdeg) {
  const auto [lo, hi] = nominal_bounds();
  return {cut_cdeg / 100.0, lo, hi};
}

// ---------------------------------------------------------------------------------------------
// Hand-made streams with ground truth.

struct StreamSpec {
  ReturnMode mode = ReturnMode::kStrongest;
  int step_cdeg = 20;               // azimuth advance per firing round: 20 at 600 RPM, 40 at 1200
  std::int64_t start_cdeg = 18000;  // unwrapped block azimuth of the first round
  int cut_cdeg = 0;                 // the cut the truth is measured from
  std::uint16_t rpm = 600;          // nominal; packets carry rpm-1, rpm, rpm+1 in turn
  std::int64_t start_ns = 1'795'348'800'000'000'000;
  // 1: all 40 channels. 4: channels 1, 5, 9, ... (0-based 0, 4, 8, ...), which still include
  // all three azimuth offsets of the nominal table; for tests that need many streams.
  int channel_stride = 1;
};

struct HandPacket {
  PacketMeta meta;
  std::vector<Point> points;
  DecodedPacket layout;
  std::int64_t first_block_u = 0;  // unwrapped block azimuth - cut of block 0
  std::int64_t last_block_u = 0;   // ... of block 9
};

struct HandStream {
  StreamSpec spec;
  std::vector<HandPacket> packets;
  std::vector<std::int64_t> point_u;      // by point id: unwrapped corrected azimuth - cut
  std::vector<std::size_t> point_packet;  // by point id: index into packets
  std::vector<std::int64_t> point_time;   // by point id: timestamp_ns
};

std::size_t id_of(const Point& p) {
  return static_cast<std::size_t>(p.x);
}

// Every block has one point per channel (every channel_stride-th; dual: in both blocks of a
// pair), so every channel that is included is present in every block.
HandStream make_stream(const StreamSpec& spec, int packet_count) {
  static const std::array<int, kChannels> offsets = nominal_offsets_cdeg();
  HandStream stream;
  stream.spec = spec;
  const int rounds = rounds_per_packet(spec.mode);
  const int returns = returns_per_firing(spec.mode);
  for (int k = 0; k < packet_count; ++k) {
    HandPacket p;
    p.meta.return_mode = spec.mode;
    p.meta.motor_rpm = static_cast<std::uint16_t>(spec.rpm - 1 + k % 3);
    p.meta.time_valid = true;
    p.meta.t0_ns = spec.start_ns +
                   (static_cast<std::int64_t>(k + 1) * rounds - 1) * kRoundPeriodNs +
                   kLastRoundEndNs;
    for (int b = 0; b < kBlocks; ++b) {
      const std::int64_t round = static_cast<std::int64_t>(k) * rounds + b / returns;
      const std::int64_t block_u = spec.start_cdeg + round * spec.step_cdeg;
      p.meta.block_azimuth_cdeg[b] = static_cast<std::uint16_t>(floor_mod(block_u, kCircle));
      if (b == 0) p.first_block_u = block_u - spec.cut_cdeg;
      if (b == kBlocks - 1) p.last_block_u = block_u - spec.cut_cdeg;
      p.layout.block_begin[b] = static_cast<std::uint16_t>(p.points.size());
      for (int c = 0; c < kChannels; c += spec.channel_stride) {
        const std::size_t id = stream.point_u.size();
        Point point;
        point.x = static_cast<float>(id);
        point.distance_m = 10.0f;
        point.channel = static_cast<std::uint8_t>(c);
        point.azimuth_cdeg = static_cast<std::uint16_t>(floor_mod(block_u + offsets[c], kCircle));
        point.timestamp_ns =
            p.meta.t0_ns + block_offset_ns(b, spec.mode) - kChannelFiringOffsetNs[c];
        point.return_type = spec.mode != ReturnMode::kDual ? ReturnType::kSingle
                            : b % 2 == 0                   ? ReturnType::kLast
                                                           : ReturnType::kStrongest;
        p.points.push_back(point);
        stream.point_u.push_back(block_u + offsets[c] - spec.cut_cdeg);
        stream.point_packet.push_back(static_cast<std::size_t>(k));
        stream.point_time.push_back(point.timestamp_ns);
      }
    }
    p.layout.block_begin[kBlocks] = static_cast<std::uint16_t>(p.points.size());
    p.layout.point_count = static_cast<std::uint16_t>(p.points.size());
    stream.packets.push_back(std::move(p));
  }
  REQUIRE(stream.point_u.size() < (std::size_t{1} << 24));  // ids stay exact in a float
  return stream;
}

// Frame storage for a whole revolution of a stream, with 10 % to spare for the seam.
std::size_t capacity_for(const StreamSpec& spec) {
  const int rounds = 36000 / spec.step_cdeg;
  return static_cast<std::size_t>(rounds * kChannels * returns_per_firing(spec.mode)) * 11 / 10;
}

// Packets to reach about `revolutions` revolutions past the cut from spec.start_cdeg.
int packets_until(const StreamSpec& spec, double revolutions) {
  const double target = revolutions * kCircle + spec.cut_cdeg;
  const double per_packet = spec.step_cdeg * rounds_per_packet(spec.mode);
  return static_cast<int>((target - static_cast<double>(spec.start_cdeg)) / per_packet);
}

// ---------------------------------------------------------------------------------------------
// Sinks.

struct Recorded {
  FrameInfo info;
  std::vector<Point> points;
  std::size_t capacity = 0;
};

// A pool of frames; finished frames are copied out and returned to the pool. `refuse(n)` makes
// the n-th acquire_frame() call (1-based) return nullptr.
class RecordingSink : public FrameSink {
 public:
  RecordingSink(std::size_t frames, std::size_t capacity,
                std::function<bool(std::uint64_t)> refuse = {})
      : storage_(frames * capacity), frames_(frames), refuse_(std::move(refuse)) {
    for (std::size_t i = 0; i < frames; ++i) {
      frames_[i].points = std::span<Point>(storage_).subspan(i * capacity, capacity);
      free_.push_back(&frames_[i]);
    }
  }

  Frame* acquire_frame() override {
    ++acquires;
    if (refuse_ && refuse_(acquires)) return nullptr;
    if (free_.empty()) return nullptr;
    Frame* frame = free_.back();
    free_.pop_back();
    // Stale contents from the previous use: the assembler must reset the frame.
    frame->info.points = 12345;
    frame->info.partial = true;
    frame->size = 7;
    return frame;
  }

  void frame_done(Frame& frame) override {
    const bool ours = &frame >= frames_.data() && &frame < frames_.data() + frames_.size();
    const bool outstanding = std::find(free_.begin(), free_.end(), &frame) == free_.end();
    CHECK(ours);
    CHECK(outstanding);  // handed back once
    recorded.push_back(
        {frame.info, {frame.used().begin(), frame.used().end()}, frame.points.size()});
    if (ours && outstanding) free_.push_back(&frame);
  }

  std::uint64_t acquires = 0;
  std::vector<Recorded> recorded;

 private:
  std::vector<Point> storage_;
  std::vector<Frame> frames_;
  std::vector<Frame*> free_;
  std::function<bool(std::uint64_t)> refuse_;
};

class NullSink : public FrameSink {
 public:
  Frame* acquire_frame() override {
    ++acquires;
    return nullptr;
  }
  void frame_done(Frame&) override { ++done; }
  std::uint64_t acquires = 0, done = 0;
};

// ---------------------------------------------------------------------------------------------
// Feeding and the expected frames.

struct ExpectedFrame {
  int segment = 0;
  std::int64_t index = 0;  // floor(U / 36000) within its segment
  std::vector<std::size_t> ids;
  bool complete = false;
};

// Feeds packets of a stream into an assembler, remembering what the contract then expects.
// A "segment" is a stretch of input the assembler treats as one stream: a new one starts after
// flush() or a discontinuity.
class Harness {
 public:
  Harness(const HandStream& stream, const FrameAssemblerConfig& config, FrameSink& sink)
      : stream_(stream),
        config_(config),
        assembler_(config, sink),
        meta_(stream.packets.size()),
        position_(stream.packets.size(), 0) {}

  void feed(std::size_t k) { feed(k, stream_.packets[k].meta); }
  // Feeds packet k with different metadata (same azimuths and points).
  void feed(std::size_t k, const PacketMeta& meta) {
    const HandPacket& p = stream_.packets[k];
    assembler_.add_packet(meta, p.points, p.layout);
    fed_.push_back({k, segment_});
    meta_[k] = meta;
    position_[k] = fed_.size();
    points_fed_ += p.points.size();
  }
  void feed_range(std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; ++k)
      feed(k);
  }
  // The next packet starts a new stream (the test expects a discontinuity there).
  void expect_new_segment() { ++segment_; }
  void flush() {
    assembler_.flush();
    ++segment_;
  }
  // Points the test expects to be dropped as late: not part of any expected frame.
  void expect_late(std::size_t id) { late_.insert(id); }

  const AssemblerStats& stats() const { return assembler_.stats(); }
  std::uint64_t points_fed() const { return points_fed_; }

  std::vector<ExpectedFrame> expected() const {
    std::map<std::pair<int, std::int64_t>, std::vector<std::size_t>> groups;
    std::map<int, std::int64_t> first_u, max_u;
    for (const Fed& f : fed_) {
      const HandPacket& p = stream_.packets[f.packet];
      if (!first_u.count(f.segment)) {
        first_u[f.segment] = p.first_block_u;
        max_u[f.segment] = p.last_block_u;
      }
      max_u[f.segment] = std::max(max_u[f.segment], p.last_block_u);
      const std::size_t first_id = id_of(p.points.front());
      for (std::size_t i = 0; i < p.points.size(); ++i) {
        const std::size_t id = first_id + i;
        if (late_.count(id)) continue;
        groups[{f.segment, floor_div(stream_.point_u[id], kCircle)}].push_back(id);
      }
    }
    std::vector<ExpectedFrame> frames;
    for (auto& [key, ids] : groups) {
      ExpectedFrame e;
      e.segment = key.first;
      e.index = key.second;
      e.ids = ids;
      std::sort(e.ids.begin(), e.ids.end());
      // Header: whole only if the stream started before the frame began for every channel,
      // and closed (not flushed) once U + the most negative offset passed the frame's end by the
      // close margin.
      const bool started_before =
          e.index * kCircle >= first_u[e.segment] + config_.relative_azimuth_max_cdeg;
      const bool closed = (e.index + 1) * kCircle <= max_u[e.segment] +
                                                         config_.relative_azimuth_min_cdeg -
                                                         FrameAssembler::kCloseMarginCdeg;
      e.complete = started_before && closed;
      frames.push_back(std::move(e));
    }
    return frames;
  }

  // The metadata packet k was fed with.
  const PacketMeta& meta_of(std::size_t packet) const { return meta_[packet]; }
  // 1-based position of packet k in the feed order (0: not fed), for "the last packet that
  // contributed".
  std::size_t feed_position(std::size_t packet) const { return position_[packet]; }

 private:
  struct Fed {
    std::size_t packet;
    int segment;
  };
  const HandStream& stream_;
  FrameAssemblerConfig config_;
  FrameAssembler assembler_;
  std::vector<Fed> fed_;
  std::vector<PacketMeta> meta_;
  std::vector<std::size_t> position_;
  std::set<std::size_t> late_;
  int segment_ = 0;
  std::uint64_t points_fed_ = 0;
};

struct CheckOptions {
  std::set<std::pair<int, std::int64_t>> partial_unchecked;  // (segment, index) to skip
};

// The recorded frames are exactly the expected ones, in order, with the FrameInfo the contract
// gives them.
void check_frames(const std::vector<Recorded>& recorded, const std::vector<ExpectedFrame>& expected,
                  const HandStream& stream, const Harness& harness,
                  const CheckOptions& options = {}) {
  REQUIRE(recorded.size() == expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const Recorded& r = recorded[i];
    const ExpectedFrame& e = expected[i];
    INFO("frame " << i << " (segment " << e.segment << ", revolution " << e.index << ")");
    std::vector<std::size_t> got;
    for (const Point& p : r.points)
      got.push_back(id_of(p));
    std::sort(got.begin(), got.end());
    CHECK(std::adjacent_find(got.begin(), got.end()) == got.end());  // no point twice
    std::size_t misplaced = 0;
    for (std::size_t id : got)
      if (!std::binary_search(e.ids.begin(), e.ids.end(), id)) ++misplaced;
    CHECK(misplaced == 0);
    CHECK(got.size() == e.ids.size());

    const FrameInfo& info = r.info;
    CHECK(info.sequence == i);
    CHECK(info.points == r.points.size());
    CHECK(info.points_dropped == 0);
    if (!options.partial_unchecked.count({e.segment, e.index})) {
      CHECK(info.partial == !e.complete);
    }

    // Times, packets, RPM, return mode and time validity from the ground truth.
    std::int64_t t_min = INT64_MAX, t_max = INT64_MIN;
    std::vector<std::size_t> packets;
    for (std::size_t id : e.ids) {
      t_min = std::min(t_min, stream.point_time[id]);
      t_max = std::max(t_max, stream.point_time[id]);
      packets.push_back(stream.point_packet[id]);
    }
    std::sort(packets.begin(), packets.end());
    packets.erase(std::unique(packets.begin(), packets.end()), packets.end());
    CHECK(info.start_ns == t_min);
    CHECK(info.end_ns == t_max);
    CHECK(info.start_ns <= info.end_ns);
    CHECK(info.packets == packets.size());
    double rpm_sum = 0;
    bool time_valid = true;
    std::size_t last_packet = packets.front();
    for (std::size_t k : packets) {
      REQUIRE(harness.feed_position(k) > 0);
      const PacketMeta& meta = harness.meta_of(k);
      rpm_sum += meta.motor_rpm;
      time_valid = time_valid && meta.time_valid;
      if (harness.feed_position(k) > harness.feed_position(last_packet)) last_packet = k;
    }
    CHECK(info.rpm == Approx(rpm_sum / static_cast<double>(packets.size())));
    CHECK(info.return_mode == harness.meta_of(last_packet).return_mode);
    CHECK(info.time_valid == time_valid);
  }
}

// Per channel, in time order, the corrected azimuths of a whole frame run from just after the cut
// (within one azimuth step) around to just before it, without wrapping in between.
void check_channel_cut(const Recorded& frame, int cut_cdeg, int step_cdeg) {
  std::array<std::vector<std::pair<std::int64_t, std::int64_t>>, kChannels> by_channel;
  for (const Point& p : frame.points)
    by_channel[p.channel].push_back(
        {p.timestamp_ns, floor_mod(p.azimuth_cdeg - cut_cdeg, kCircle)});
  for (int c = 0; c < kChannels; ++c) {
    INFO("channel " << c);
    auto& points = by_channel[c];
    REQUIRE_FALSE(points.empty());
    std::stable_sort(points.begin(), points.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::size_t wraps = 0;
    for (std::size_t i = 1; i < points.size(); ++i)
      if (points[i].second < points[i - 1].second) ++wraps;
    CHECK(wraps == 0);
    CHECK(points.front().second < step_cdeg);
    CHECK(points.back().second >= kCircle - step_cdeg);
  }
}

std::uint64_t stored_points(const std::vector<Recorded>& recorded) {
  std::uint64_t n = 0;
  for (const Recorded& r : recorded)
    n += r.info.points;
  return n;
}

struct ModeCase {
  ReturnMode mode;
  int step_cdeg;
  std::uint16_t rpm;
};
const ModeCase kModeCases[] = {{ReturnMode::kStrongest, 20, 600},
                               {ReturnMode::kDual, 20, 600},
                               {ReturnMode::kLast, 40, 1200},
                               {ReturnMode::kDual, 40, 1200}};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Hand-made streams.

TEST_CASE("every point lands in the revolution of its corrected azimuth - cut per channel",
          "[assembler]") {
  // A slow build checks its memory and UB on two of the cuts, each mode still (under ASan this
  // matrix took 29 s, 4 s in release: the checks' loops, compiled at -O0 there).
  const std::vector<int> cuts =
      test::kSlowBuild ? std::vector<int>{0, 35999} : std::vector<int>{0, 9000, 35999, 12345};
  for (const ModeCase& mc : kModeCases) {
    for (int cut : cuts) {
      INFO("mode " << to_string(mc.mode) << ", step " << mc.step_cdeg << ", cut " << cut);
      StreamSpec spec;
      spec.mode = mc.mode;
      spec.step_cdeg = mc.step_cdeg;
      spec.rpm = mc.rpm;
      spec.cut_cdeg = cut;
      spec.start_cdeg = cut + 12345;  // mid-revolution
      const HandStream stream = make_stream(spec, packets_until(spec, 4.5));
      RecordingSink sink(2, capacity_for(spec));
      Harness h(stream, config_for(cut), sink);
      h.feed_range(0, stream.packets.size());
      h.flush();

      const auto expected = h.expected();
      // Started mid-revolution, ended mid-revolution: partial, 3 whole revolutions, partial.
      REQUIRE(expected.size() == 5);
      CHECK_FALSE(expected.front().complete);
      CHECK_FALSE(expected.back().complete);
      for (std::size_t i = 1; i + 1 < expected.size(); ++i)
        CHECK(expected[i].complete);
      check_frames(sink.recorded, expected, stream, h);

      for (std::size_t i = 1; i + 1 < sink.recorded.size(); ++i) {
        INFO("frame " << i);
        check_channel_cut(sink.recorded[i], cut, mc.step_cdeg);
      }
      const AssemblerStats& s = h.stats();
      CHECK(s.frames_complete == 3);
      CHECK(s.frames_partial == 2);
      CHECK(s.discontinuities == 0);
      CHECK(s.azimuth_backward_steps == 0);
      CHECK(s.points_late == 0);
      CHECK(s.frames_dropped == 0);
      CHECK(s.points_dropped_full == 0);
      CHECK(s.points_dropped_no_frame == 0);
      CHECK(stored_points(sink.recorded) == h.points_fed());
    }
  }
}

TEST_CASE("the first frame is partial wherever the stream starts", "[assembler]") {
  // Starts at, just after, and just before the cut: near the cut some channels have crossed it
  // and some have not, so the first two frames can both be partial (the contract's rule).
  for (std::int64_t start : {0, 100, 600, 18000, 35500, 35900, 35999}) {
    for (int cut : {0, 9000}) {
      INFO("start " << start << " cut " << cut);
      StreamSpec spec;
      spec.cut_cdeg = cut;
      spec.start_cdeg = cut + start;
      spec.channel_stride = 4;
      const HandStream stream = make_stream(spec, packets_until(spec, 3.5));
      RecordingSink sink(2, capacity_for(spec));
      Harness h(stream, config_for(cut), sink);
      h.feed_range(0, stream.packets.size());
      h.flush();
      const auto expected = h.expected();
      REQUIRE(expected.size() >= 4);
      CHECK_FALSE(expected.front().complete);
      check_frames(sink.recorded, expected, stream, h);
      REQUIRE_FALSE(sink.recorded.empty());
      CHECK(sink.recorded.front().info.partial);
      CHECK(sink.recorded.back().info.partial);
    }
  }
}

TEST_CASE("FrameInfo: sequence, times, packets, RPM, return mode and time validity",
          "[assembler]") {
  StreamSpec spec;
  spec.mode = ReturnMode::kDual;
  const HandStream stream = make_stream(spec, packets_until(spec, 3.5));
  RecordingSink sink(2, capacity_for(spec));
  Harness h(stream, config_for(0), sink);
  // One packet in the middle of revolution 2 has no valid absolute time; the last packets report
  // another return mode (the frame takes the last contributing packet's).
  const std::size_t bad_time = static_cast<std::size_t>(packets_until(spec, 2.5));
  const std::size_t mode_change = stream.packets.size() - 3;
  for (std::size_t k = 0; k < stream.packets.size(); ++k) {
    PacketMeta meta = stream.packets[k].meta;
    if (k == bad_time) meta.time_valid = false;
    if (k >= mode_change) meta.return_mode = ReturnMode::kLast;
    meta.motor_rpm = static_cast<std::uint16_t>(590 + (k * 7) % 21);
    h.feed(k, meta);
  }
  h.flush();
  const auto expected = h.expected();
  check_frames(sink.recorded, expected, stream, h);
  REQUIRE(sink.recorded.size() == 4);
  CHECK(sink.recorded[0].info.time_valid);
  CHECK(sink.recorded[1].info.time_valid);
  CHECK_FALSE(sink.recorded[2].info.time_valid);
  CHECK(sink.recorded[3].info.time_valid);
  CHECK(sink.recorded[3].info.return_mode == ReturnMode::kLast);
  CHECK(sink.recorded[2].info.return_mode == ReturnMode::kDual);
  // A whole revolution at 600 RPM dual: 360 packets of 1° each, plus the ~8.3° seam across which
  // channels cross the cut at different packets.
  for (std::size_t i = 1; i <= 2; ++i) {
    CHECK(sink.recorded[i].info.packets >= 368);
    CHECK(sink.recorded[i].info.packets <= 370);
    CHECK(sink.recorded[i].info.rpm > 590);
    CHECK(sink.recorded[i].info.rpm < 610);
  }
}

TEST_CASE("flush closes open frames as partial and the next packet starts a new stream",
          "[assembler]") {
  StreamSpec spec;
  const HandStream stream = make_stream(spec, packets_until(spec, 4.5));
  RecordingSink sink(2, capacity_for(spec));
  Harness h(stream, config_for(0), sink);
  h.flush();  // nothing open: nothing happens
  CHECK(sink.recorded.empty());
  const std::size_t half = static_cast<std::size_t>(packets_until(spec, 2.5));
  h.feed_range(0, half);
  const std::size_t before_flush = sink.recorded.size();
  h.flush();
  CHECK(sink.recorded.size() == before_flush + 1);
  CHECK(sink.recorded.back().info.partial);
  h.flush();  // twice is harmless
  CHECK(sink.recorded.size() == before_flush + 1);
  h.feed_range(half, stream.packets.size());
  h.flush();
  check_frames(sink.recorded, h.expected(), stream, h);
  CHECK(h.stats().discontinuities == 0);
  // Revolution 2 was split by the flush: both halves are partial.
  CHECK(h.stats().frames_partial == 4);
  CHECK(h.stats().frames_complete == 2);
}

TEST_CASE("losing the packets around the cut keeps every point in its own revolution",
          "[assembler]") {
  for (const ModeCase& mc : kModeCases) {
    const int per_packet = mc.step_cdeg * rounds_per_packet(mc.mode);
    // Up to just under 90° of azimuth and under half a revolution of time.
    const int max_k = (9000 - mc.step_cdeg) / per_packet - 1;
    for (int cut : {0, 9000}) {
      StreamSpec spec;
      spec.mode = mc.mode;
      spec.step_cdeg = mc.step_cdeg;
      spec.rpm = mc.rpm;
      spec.cut_cdeg = cut;
      spec.start_cdeg = cut + 18000;
      spec.channel_stride = 4;
      const HandStream stream = make_stream(spec, packets_until(spec, 4.5));
      RecordingSink reference_sink(2, capacity_for(spec));
      Harness reference(stream, config_for(cut), reference_sink);
      reference.feed_range(0, stream.packets.size());
      reference.flush();
      // The packet whose blocks cross the cut of revolution 2.
      std::size_t straddle = 0;
      while (stream.packets[straddle].last_block_u < 2 * kCircle)
        ++straddle;
      REQUIRE(stream.packets[straddle].first_block_u <= 2 * kCircle);

      // A slow build: five of the nine losses (24 s under ASan, 1.6 s in release, as above).
      const std::vector<int> losses = test::kSlowBuild
                                          ? std::vector<int>{1, 2, 5, 20, max_k}
                                          : std::vector<int>{1, 2, 3, 4, 5, 8, 13, 20, max_k};
      for (int k_lost : losses) {
        INFO("mode " << to_string(mc.mode) << " step " << mc.step_cdeg << " lost " << k_lost
                     << " cut " << cut);
        // K packets around the straddling one.
        const std::size_t lost_begin = straddle - static_cast<std::size_t>(k_lost / 2);
        const std::size_t lost_end = lost_begin + static_cast<std::size_t>(k_lost);
        RecordingSink sink(2, capacity_for(spec));
        Harness h(stream, config_for(cut), sink);
        h.feed_range(0, lost_begin);
        h.feed_range(lost_end, stream.packets.size());
        h.flush();

        CheckOptions options;
        options.partial_unchecked = {{0, 1}, {0, 2}};  // the two frames that lost points
        check_frames(sink.recorded, h.expected(), stream, h, options);
        CHECK(sink.recorded.size() == reference_sink.recorded.size());
        CHECK(h.stats().discontinuities == 0);
        CHECK(h.stats().points_late == 0);
        CHECK(stored_points(sink.recorded) == h.points_fed());
        // Frames away from the loss are untouched and still complete.
        REQUIRE(sink.recorded.size() == 5);
        CHECK_FALSE(sink.recorded[3].info.partial);
        CHECK(sink.recorded[3].info.points == reference_sink.recorded[3].info.points);
      }
    }
  }
}

TEST_CASE("a loss of more than 90° of azimuth is a discontinuity: close as partial, restart",
          "[assembler]") {
  // 600 RPM single return: 2° per packet, 555.6 µs apart; half a revolution = 90 packets.
  // 46 lost packets = 92.2° in 25.6 ms: only the azimuth tells. More than 90 lost packets are
  // also more than half a revolution of time; 180 lost packets are exactly one revolution, so
  // the azimuth looks continuous and only the time tells.
  for (int k_lost : {46, 60, 100, 150, 180, 360}) {
    INFO(k_lost << " packets lost");
    StreamSpec spec;
    spec.start_cdeg = 18000;
    const HandStream stream = make_stream(spec, packets_until(spec, 6.5));
    // Lose them from the middle of revolution 2 on.
    const auto lost_begin = static_cast<std::size_t>(packets_until(spec, 2.4));
    const std::size_t lost_end = lost_begin + static_cast<std::size_t>(k_lost);
    RecordingSink sink(2, capacity_for(spec));
    Harness h(stream, config_for(0), sink);
    h.feed_range(0, lost_begin);
    h.expect_new_segment();
    h.feed_range(lost_end, stream.packets.size());
    h.flush();

    CHECK(h.stats().discontinuities == 1);
    CHECK(h.stats().points_late == 0);
    CHECK(h.stats().azimuth_backward_steps == 0);
    const auto expected = h.expected();
    check_frames(sink.recorded, expected, stream, h);
    // Segment 0: partial, revolution 1 whole, partial (cut off); segment 1 starts partial.
    REQUIRE(sink.recorded.size() >= 5);
    CHECK(sink.recorded[0].info.partial);
    CHECK_FALSE(sink.recorded[1].info.partial);
    CHECK(sink.recorded[2].info.partial);
    CHECK(sink.recorded[3].info.partial);
    CHECK(stored_points(sink.recorded) == h.points_fed());
  }
}

TEST_CASE("a packet-time gap of more than half a revolution is a discontinuity", "[assembler]") {
  for (const ModeCase& mc : kModeCases) {
    const std::int64_t half_revolution_ns = 30'000'000'000LL / mc.rpm;
    for (const bool restart : {false, true}) {
      // The azimuth stays continuous; only the clock jumps (the time between the two packets is
      // one packet period plus the jump).
      const std::int64_t jump_ns =
          restart ? half_revolution_ns + 1'000'000 : half_revolution_ns - 2'000'000;
      INFO("mode " << to_string(mc.mode) << " rpm " << mc.rpm << " jump " << jump_ns);
      StreamSpec spec;
      spec.mode = mc.mode;
      spec.step_cdeg = mc.step_cdeg;
      spec.rpm = mc.rpm;
      spec.channel_stride = 4;
      const HandStream stream = make_stream(spec, packets_until(spec, 4.5));
      const auto at = static_cast<std::size_t>(packets_until(spec, 2.5));
      RecordingSink sink(2, capacity_for(spec));
      Harness h(stream, config_for(0), sink);
      h.feed_range(0, at);
      if (restart) h.expect_new_segment();
      for (std::size_t k = at; k < stream.packets.size(); ++k) {
        PacketMeta meta = stream.packets[k].meta;
        meta.t0_ns += jump_ns;
        meta.motor_rpm = mc.rpm;
        h.feed(k, meta);
      }
      h.flush();
      CHECK(h.stats().discontinuities == (restart ? 1u : 0u));
      check_frames(sink.recorded, h.expected(), stream, h);
      CHECK(sink.recorded.size() == (restart ? 6u : 5u));
    }
  }
}

TEST_CASE("packet times that are not valid are not used to find gaps", "[assembler]") {
  // Without a valid date t0 is just the µs field, which wraps every second.
  StreamSpec spec;
  spec.channel_stride = 4;
  const HandStream stream = make_stream(spec, packets_until(spec, 12.5));  // 1.2 s
  RecordingSink sink(2, capacity_for(spec));
  Harness h(stream, config_for(0), sink);
  for (std::size_t k = 0; k < stream.packets.size(); ++k) {
    PacketMeta meta = stream.packets[k].meta;
    meta.time_valid = false;
    meta.t0_ns %= 1'000'000'000;
    h.feed(k, meta);
  }
  h.flush();
  CHECK(h.stats().discontinuities == 0);
  check_frames(sink.recorded, h.expected(), stream, h);
  for (const Recorded& r : sink.recorded)
    CHECK_FALSE(r.info.time_valid);
}

TEST_CASE("two swapped packets: a backward step, late points counted, nothing else moves",
          "[assembler]") {
  for (const ModeCase& mc : kModeCases) {
    INFO("mode " << to_string(mc.mode) << " step " << mc.step_cdeg);
    StreamSpec spec;
    spec.mode = mc.mode;
    spec.step_cdeg = mc.step_cdeg;
    spec.rpm = mc.rpm;
    const HandStream stream = make_stream(spec, packets_until(spec, 4.5));
    const auto [lo, hi] = nominal_bounds();
    (void)hi;

    {
      INFO("in the middle of a revolution");
      const auto a = static_cast<std::size_t>(packets_until(spec, 2.5));
      RecordingSink sink(2, capacity_for(spec));
      Harness h(stream, config_for(0), sink);
      h.feed_range(0, a);
      h.feed(a + 1);
      h.feed(a);
      h.feed_range(a + 2, stream.packets.size());
      h.flush();
      CHECK(h.stats().azimuth_backward_steps == 1);
      CHECK(h.stats().points_late == 0);
      CHECK(h.stats().discontinuities == 0);
      check_frames(sink.recorded, h.expected(), stream, h);
    }
    {
      INFO("across the cut: the earlier packet's points of the closed revolution are late");
      // A, the last packet with points of revolution 1, arrives after B, the first packet after
      // which U + (most negative offset) has passed the cut of revolution 2 by the close margin
      // (so revolution 1 is closed): A's points of revolution 1 are late, counted. (Whether the
      // frame that lost them is partial depends on how much of it they were: the coverage sees a
      // hole of half a packet's azimuth, not a sliver at its edge; docs/decoding.md.)
      std::size_t b = 1;
      while (stream.packets[b].last_block_u + lo <
             2 * kCircle + 60 + FrameAssembler::kCloseMarginCdeg)
        ++b;
      std::size_t a = 0;
      for (std::size_t k = 0; k < b; ++k) {
        if (stream.packets[k].first_block_u + lo < 2 * kCircle) a = k;
      }
      std::size_t late = 0;
      RecordingSink sink(2, capacity_for(spec));
      Harness h(stream, config_for(0), sink);
      const std::size_t first_a = id_of(stream.packets[a].points.front());
      for (std::size_t i = 0; i < stream.packets[a].points.size(); ++i) {
        if (floor_div(stream.point_u[first_a + i], kCircle) < 2) {
          h.expect_late(first_a + i);
          ++late;
        }
      }
      REQUIRE(late > 0);
      h.feed_range(0, a);
      h.feed(b);
      h.feed_range(a, b);
      h.feed_range(b + 1, stream.packets.size());
      h.flush();
      CHECK(h.stats().azimuth_backward_steps == 1);
      CHECK(h.stats().points_late == late);
      CHECK(h.stats().discontinuities == 0);
      CheckOptions options;
      options.partial_unchecked.insert({0, 1});
      check_frames(sink.recorded, h.expected(), stream, h, options);
      CHECK(stored_points(sink.recorded) + h.stats().points_late == h.points_fed());
    }
  }
}

TEST_CASE("no free frame: frames and their points are dropped and counted", "[assembler]") {
  StreamSpec spec;
  spec.mode = ReturnMode::kDual;
  const HandStream stream = make_stream(spec, packets_until(spec, 4.5));

  SECTION("the sink never has a frame") {
    NullSink sink;
    Harness h(stream, config_for(0), sink);
    h.feed_range(0, stream.packets.size());
    h.flush();
    const auto expected = h.expected();
    const AssemblerStats& s = h.stats();
    CHECK(sink.done == 0);
    CHECK(s.frames_dropped == expected.size());
    CHECK(s.frames_complete == 0);
    CHECK(s.frames_partial == 0);
    CHECK(s.points_dropped_no_frame == h.points_fed());
    CHECK(s.points_late == 0);
    CHECK(s.points_dropped_full == 0);
  }
  SECTION("some acquires fail: sequence numbers show the gaps") {
    // The 2nd, 3rd and 5th frames find no free frame.
    RecordingSink sink(3, capacity_for(spec),
                       [](std::uint64_t n) { return n == 2 || n == 3 || n == 5; });
    Harness h(stream, config_for(0), sink);
    h.feed_range(0, stream.packets.size());
    h.flush();
    const auto expected = h.expected();
    REQUIRE(expected.size() == 5);
    const AssemblerStats& s = h.stats();
    CHECK(s.frames_dropped == 3);
    REQUIRE(sink.recorded.size() == 2);
    CHECK(sink.recorded[0].info.sequence == 0);
    CHECK(sink.recorded[1].info.sequence == 3);
    std::uint64_t dropped_points = 0;
    for (std::size_t i : {1, 2, 4})
      dropped_points += expected[i].ids.size();
    CHECK(s.points_dropped_no_frame == dropped_points);
    CHECK(stored_points(sink.recorded) + s.points_dropped_no_frame + s.points_late +
              s.points_dropped_full ==
          h.points_fed());
    // The frames that were had are right.
    CHECK(sink.recorded[0].info.points == expected[0].ids.size());
    CHECK(sink.recorded[1].info.points == expected[3].ids.size());
    CHECK_FALSE(sink.recorded[1].info.partial);
  }
}

TEST_CASE("frames that fill up drop the rest of their points and say how many", "[assembler]") {
  StreamSpec spec;
  const HandStream stream = make_stream(spec, packets_until(spec, 3.5));
  const std::size_t capacity = 5000;
  RecordingSink sink(2, capacity);
  Harness h(stream, config_for(0), sink);
  h.feed_range(0, stream.packets.size());
  h.flush();
  const auto expected = h.expected();
  REQUIRE(sink.recorded.size() == expected.size());
  std::uint64_t dropped = 0;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    INFO("frame " << i);
    const Recorded& r = sink.recorded[i];
    const std::size_t want = expected[i].ids.size();
    REQUIRE(want > capacity);
    CHECK(r.info.points == capacity);
    CHECK(r.points.size() == capacity);
    CHECK(r.info.points_dropped == want - capacity);
    dropped += want - capacity;
    for (const Point& p : r.points)
      CHECK(std::binary_search(expected[i].ids.begin(), expected[i].ids.end(), id_of(p)));
    CHECK(r.info.sequence == i);
  }
  CHECK(h.stats().points_dropped_full == dropped);
  CHECK(stored_points(sink.recorded) + h.stats().points_dropped_full == h.points_fed());
}

TEST_CASE("a full frame's packet count, RPM and time validity cover only the points it kept",
          "[assembler]") {
  // FrameInfo: packets = "packets that contributed at least one point"; rpm = mean "over those
  // packets"; time_valid = "every contributing packet had a valid absolute time". Once a frame is
  // full, later packets contribute nothing to it.
  StreamSpec spec;
  const HandStream stream = make_stream(spec, packets_until(spec, 2.5));
  const std::size_t capacity = 4000;  // 10 packets of 400 points
  RecordingSink sink(2, capacity);
  Harness h(stream, config_for(0), sink);
  // Revolution 1 starts around packet 90 (U 36000) and is full about ten packets later. Packets
  // from 20 after its start on report 700 RPM instead of ~600, and one of them has no valid time.
  const auto first = static_cast<std::size_t>(packets_until(spec, 1.0));
  for (std::size_t k = 0; k < stream.packets.size(); ++k) {
    PacketMeta meta = stream.packets[k].meta;
    if (k >= first + 20) meta.motor_rpm = 700;
    if (k == first + 40) meta.time_valid = false;
    h.feed(k, meta);
  }
  h.flush();
  REQUIRE(sink.recorded.size() == 3);
  const Recorded& full = sink.recorded[1];
  REQUIRE(full.info.points == capacity);
  REQUIRE(full.info.points_dropped > 0);
  std::set<std::size_t> kept;
  double rpm_sum = 0;
  for (const Point& p : full.points)
    kept.insert(stream.point_packet[id_of(p)]);
  for (std::size_t k : kept)
    rpm_sum += h.meta_of(k).motor_rpm;
  CHECK(full.info.packets == kept.size());
  CHECK(full.info.rpm == Approx(rpm_sum / static_cast<double>(kept.size())));
  CHECK(full.info.time_valid);
}

namespace {

// Frames whose storage is bytes in an output layout, as the daemon's arenas.
class EncodedSink : public FrameSink {
 public:
  EncodedSink(std::size_t frames, std::size_t capacity, PcdFormat format)
      : storage_(frames * capacity * pcd_point_bytes(format.layout)), frames_(frames) {
    const std::size_t bytes = capacity * pcd_point_bytes(format.layout);
    for (std::size_t i = 0; i < frames; ++i) {
      frames_[i].encoded = std::span(storage_).subspan(i * bytes, bytes);
      frames_[i].format = format;
      free_.push_back(&frames_[i]);
    }
  }
  Frame* acquire_frame() override {
    if (free_.empty()) return nullptr;
    Frame* frame = free_.back();
    free_.pop_back();
    frame->reference_ns = 42;  // stale: the assembler must set it
    return frame;
  }
  void frame_done(Frame& frame) override {
    CHECK(frame.used().empty());
    CHECK(frame.reference_ns == frame.info.start_ns);
    const auto bytes = frame.used_bytes();
    recorded.push_back({frame.info, {bytes.begin(), bytes.end()}});
    free_.push_back(&frame);
  }
  std::vector<std::pair<FrameInfo, std::vector<std::uint8_t>>> recorded;

 private:
  std::vector<std::uint8_t> storage_;
  std::vector<Frame> frames_;
  std::vector<Frame*> free_;
};

float f32_at(const std::vector<std::uint8_t>& bytes, std::size_t at) {
  float v;
  std::memcpy(&v, bytes.data() + at, 4);
  return v;
}

}  // namespace

TEST_CASE("frames kept encoded hold their points' bytes in the output layout, reordered or not",
          "[assembler][pcd]") {
  StreamSpec spec;
  spec.mode = ReturnMode::kDual;
  const HandStream stream = make_stream(spec, packets_until(spec, 3.5));
  // The first two packets swapped: the first frame's earliest points come after later ones, so
  // its relative times are rebased when it closes. Two more swapped in the middle.
  const std::size_t middle = static_cast<std::size_t>(packets_until(spec, 1.5));
  std::vector<std::size_t> order(stream.packets.size());
  for (std::size_t k = 0; k < order.size(); ++k)
    order[k] = k;
  std::swap(order[0], order[1]);
  std::swap(order[middle], order[middle + 1]);

  RecordingSink as_points(2, capacity_for(spec));
  {
    Harness h(stream, config_for(0), as_points);
    for (const std::size_t k : order)
      h.feed(k);
    h.flush();
  }
  REQUIRE(as_points.recorded.size() >= 3);
  for (const PcdLayout layout :
       {PcdLayout::kPcl, PcdLayout::kPandarcap, PcdLayout::kVelodyne, PcdLayout::kAutoware}) {
    for (const Axes axes : {Axes::kHesai, Axes::kRos}) {
      INFO("layout " << to_string(layout) << ", axes " << to_string(axes));
      const PcdFormat format{layout, axes};
      EncodedSink encoded(2, capacity_for(spec), format);
      Harness h(stream, config_for(0), encoded);
      for (const std::size_t k : order)
        h.feed(k);
      h.flush();
      REQUIRE(encoded.recorded.size() == as_points.recorded.size());
      const std::size_t step = pcd_point_bytes(layout);
      for (std::size_t f = 0; f < encoded.recorded.size(); ++f) {
        INFO("frame " << f);
        const auto& [info, bytes] = encoded.recorded[f];
        const auto& points = as_points.recorded[f];
        CHECK(info.sequence == points.info.sequence);
        CHECK(info.start_ns == points.info.start_ns);
        REQUIRE(bytes.size() == points.points.size() * step);
        // What encoding the finished frame's points afterwards gives, against its start.
        std::vector<std::uint8_t> expected(bytes.size());
        encode_pcd_points(points.points, expected, format,
                          PcdFrameContext{points.info.start_ns, points.info.return_mode});
        if (layout != PcdLayout::kVelodyne) {
          CHECK(bytes == expected);
          continue;
        }
        // velodyne's F4 time, rebased in float: within a few ns of encoding it directly.
        for (std::size_t at = 0; at < bytes.size(); at += step) {
          CHECK(std::equal(bytes.begin() + at, bytes.begin() + at + 18, expected.begin() + at));
          CHECK(f32_at(bytes, at + 18) == Approx(f32_at(expected, at + 18)).margin(5e-9));
        }
      }
    }
  }
}
