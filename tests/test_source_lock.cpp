// One sensor per daemon (core/decode/source_lock.hpp): which source's datagrams are the sensor's,
// with sensor_ip and without, and what another sensor on the port looks like.
#include <array>
#include <catch2/catch.hpp>
#include <cstdint>

#include "core/decode/source_lock.hpp"
#include "core/ipv4.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "core/units.hpp"

using namespace pandarcap;

namespace {

constexpr std::uint32_t kA = 0x7F000001;  // 127.0.0.1
constexpr std::uint32_t kB = 0x7F000002;  // 127.0.0.2

struct Datagrams {
  Datagrams() {
    SyntheticSensor sensor(SyntheticSensorConfig{});
    packet_size = sensor.next(packet);
  }
  std::span<const std::uint8_t> valid() const { return std::span(packet).first(packet_size); }
  std::span<const std::uint8_t> garbage() const { return std::span(packet).first(100); }
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  std::size_t packet_size = 0;
};

using V = SourceLock::Verdict;

}  // namespace

TEST_CASE("source lock: without sensor_ip, the first source to send a packet is the sensor's",
          "[source][faults]") {
  const Datagrams d;
  SourceLock lock(std::nullopt);
  // Before any packet, anything goes to the decoder (which rejects and counts what is no packet).
  CHECK(lock.judge(kB, 5000, d.garbage(), 0) == V::kSensor);
  CHECK(lock.sensor_source() == 0);
  CHECK(lock.judge(kA, 10000, d.valid(), 1 * kNsPerMillisecond) == V::kSensor);
  CHECK(lock.sensor_source() == pack_ipv4_source(kA, 10000));
  // Another address: a packet is another sensor, named; anything else foreign.
  CHECK(lock.judge(kB, 10000, d.valid(), 2 * kNsPerMillisecond) == V::kOtherSensor);
  CHECK(lock.other_source() == pack_ipv4_source(kB, 10000));
  CHECK(lock.judge(kB, 5000, d.garbage(), 3 * kNsPerMillisecond) == V::kForeign);
  // The sensor's address from another port (a restarted sensor, a new socket): still the sensor.
  CHECK(lock.judge(kA, 10001, d.valid(), 4 * kNsPerMillisecond) == V::kSensor);
  CHECK(lock.sensor_source() == pack_ipv4_source(kA, 10001));
  CHECK(lock.judge(kA, 10001, d.garbage(), 5 * kNsPerMillisecond) == V::kSensor);
  // Two sensors sending together for a while: the lock never moves.
  for (std::int64_t t = 6; t < 3000; t += 10) {
    CHECK(lock.judge(kA, 10001, d.valid(), t * kNsPerMillisecond) == V::kSensor);
    CHECK(lock.judge(kB, 10000, d.valid(), (t + 5) * kNsPerMillisecond) == V::kOtherSensor);
  }
  CHECK(lock.source_changes() == 0);
  // The sensor silent for a second, another sending: it moved there, counted.
  CHECK(lock.judge(kB, 10000, d.valid(), 3995 * kNsPerMillisecond) ==
        V::kOtherSensor);  // 999 ms: not yet
  CHECK(lock.judge(kB, 10000, d.valid(), 3996 * kNsPerMillisecond) == V::kSensor);
  CHECK(lock.source_changes() == 1);
  CHECK(lock.sensor_source() == pack_ipv4_source(kB, 10000));
  CHECK(lock.other_source() == pack_ipv4_source(kA, 10001));
  CHECK(lock.judge(kA, 10001, d.valid(), 3997 * kNsPerMillisecond) == V::kOtherSensor);
}

TEST_CASE("source lock: with sensor_ip, that address is the sensor's, and never another",
          "[source][faults]") {
  const Datagrams d;
  SourceLock lock(kB);
  CHECK(lock.judge(kA, 10000, d.valid(), 0) == V::kOtherSensor);  // first, and still not it
  CHECK(lock.other_source() == pack_ipv4_source(kA, 10000));
  CHECK(lock.judge(kA, 10000, d.garbage(), 1) == V::kForeign);
  CHECK(lock.judge(kB, 2368, d.valid(), 2) == V::kSensor);
  CHECK(lock.sensor_source() == pack_ipv4_source(kB, 2368));
  CHECK(lock.judge(kB, 2368, d.garbage(), 3) == V::kSensor);  // the decoder rejects it
  // Silent for ten seconds: sensor_ip is still the sensor.
  CHECK(lock.judge(kA, 10000, d.valid(), 10'000 * kNsPerMillisecond) == V::kOtherSensor);
  CHECK(lock.source_changes() == 0);
}

TEST_CASE("source lock: the packed sources read as addresses", "[source][faults]") {
  std::string text;
  append_ipv4_source(text, pack_ipv4_source(0xC0A801C9, 2368));
  CHECK(text == "192.168.1.201:2368");
  text.clear();
  append_ipv4_source(text, 0);
  CHECK(text == "none");
}
