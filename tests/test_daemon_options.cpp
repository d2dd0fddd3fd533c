// The daemon's start-up in pieces: what the configuration means for each thread
// (daemon/daemon_options.hpp), command-line keys checked as the file checks them
// (set_config_value), and the threads stopped in the reverse of their start (PipelineThreads).
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "config/command_line.hpp"
#include "config/config_loader.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/pipeline_types.hpp"

using namespace pandarcap;

TEST_CASE("command-line keys get the file's type and range checks, with the file's words",
          "[config][cli]") {
  DaemonConfig config;
  set_config_value(config, "sensor.max_range", "150.5", "cli");
  CHECK(config.sensor.max_range == 150.5);
  set_config_value(config, "sensor.data_port", "2369", "cli");
  CHECK(config.sensor.data_port == 2369);
  set_config_value(config, "sensor.firing_time_correction", "true", "cli");
  CHECK(config.sensor.firing_time_correction);
  set_config_value(config, "decoder", "scalar", "cli");
  CHECK(config.decoder == "scalar");

  CHECK_THROWS_WITH(set_config_value(config, "sensor.data_port", "70000", "cli"),
                    "cli: sensor.data_port: 70000 is out of range (1..65535)");
  CHECK_THROWS_WITH(set_config_value(config, "sensor.data_port", "23a", "cli"),
                    "cli: sensor.data_port: expected an integer, found \"23a\"");
  CHECK_THROWS_WITH(set_config_value(config, "sensor.max_range", "far", "cli"),
                    "cli: sensor.max_range: expected a number, found \"far\"");
  CHECK_THROWS_WITH(set_config_value(config, "sensor.cut_angle", "360", "cli"),
                    Catch::Contains("360 is out of range"));
  CHECK_THROWS_WITH(set_config_value(config, "sensor.host_ip", "1.2.3", "cli"),
                    Catch::Contains("is not an IPv4 address"));
  CHECK_THROWS_WITH(set_config_value(config, "sensor.nope", "1", "cli"),
                    "cli: sensor.nope: not a configuration key");
  // Refused values leave the configuration as it was.
  CHECK(config.sensor.data_port == 2369);

  // The same value in a file is refused with the same problem.
  CHECK_THROWS_WITH(parse_config("[sensor]\ndata_port = 70000\n", "f.toml"),
                    Catch::EndsWith("sensor.data_port: 70000 is out of range (1..65535)"));
}

TEST_CASE("every command-line key option names a key the configuration has", "[config][cli]") {
  for (const KeyOption& option : kKeyOptions) {
    INFO(option.option);
    REQUIRE(find_key_option(option.option) == &option);
    // A flag's "true" is accepted; another option's value may be wrong for its key, but the key
    // itself is always one the configuration has.
    const auto problem = key_option_problem(option, option.flag ? "true" : "__not_a_value__");
    if (option.flag) {
      CHECK_FALSE(problem);
    } else if (problem) {
      CHECK_THAT(*problem, !Catch::Contains("not a configuration key"));
    }
  }
  CHECK(find_key_option("--replay") == nullptr);
}

TEST_CASE("the writer's options follow the configuration's directories", "[daemon][options]") {
  DaemonConfig config;
  config.output.directory = "/data/run";
  WriterOptions wo = writer_options(config);
  CHECK(wo.output_dir == "/data/run");
  CHECK(wo.health_dir == "/data/run/health");
  CHECK(wo.prometheus_file == "/data/run/health/pandarcap.prom");
  config.health.directory = "/var/lib/node_exporter";
  config.health.prometheus_file = "/var/lib/textfile/pandarcap.prom";
  config.output.pcap_max_files = 7;
  config.sensor.rotation_speed = 1200;
  wo = writer_options(config);
  CHECK(wo.health_dir == "/var/lib/node_exporter");
  CHECK(wo.prometheus_file == "/var/lib/textfile/pandarcap.prom");
  CHECK(wo.pcap_max_files == 7);
  CHECK(wo.expected_rpm == 1200);
}

// The lzf compressor and the MCAP file are sized for the frames the arenas hold: arena_points(),
// at least a revolution of the model, whatever arenas.points_per_frame asks (found by a hostile
// tester: with points_per_frame = 1000, every MCAP point cloud was refused as too large).
TEST_CASE("the writer's frame capacity is the arenas', for every model and points_per_frame",
          "[daemon][options]") {
  DaemonConfig config;
  for (const std::uint32_t asked : {1000u, 100'000u, 180'000u, 10'000'000u}) {
    for (const std::optional<SensorModelId> model :
         {std::optional<SensorModelId>{}, std::optional{SensorModelId::kPandar40P},
          std::optional{SensorModelId::kPandarQT128}}) {
      CAPTURE(asked, model.has_value());
      config.arenas.points_per_frame = asked;
      const WriterOptions wo = writer_options(config, model);
      CHECK(wo.max_frame_points == arena_points(config, model));
      CHECK(wo.mcap_file.max_frame_points == arena_points(config, model));
      CHECK(wo.max_frame_points >= asked);
    }
  }
}

TEST_CASE("the decoder's options: a replay waits for the writer, live capture measures latency",
          "[daemon][options]") {
  DaemonConfig config;
  config.sensor.min_range = 1.5;
  config.sensor.cut_angle = 90;
  config.output.frame_decimation = 3;
  RunSource live;
  RunSource replay;
  replay.kind = RunSource::Kind::kReplay;
  replay.replay_path = "x.pcap";
  const DecodeWorkerOptions a = decode_worker_options(config, DecoderTarget::kScalar, live);
  CHECK_FALSE(a.lossless);
  CHECK(a.measure_latency);
  CHECK(a.decoder.decoder.min_range_m == 1.5);
  CHECK(a.decoder.cut_angle_deg == 90);
  CHECK(a.frame_decimation == 3);
  const DecodeWorkerOptions b = decode_worker_options(config, DecoderTarget::kScalar, replay);
  CHECK(b.lossless);
  CHECK_FALSE(b.measure_latency);
}

TEST_CASE("the simulated sensor's socket is loopback on a free port unless --port",
          "[daemon][options]") {
  DaemonConfig config;
  config.sensor.host_ip = "10.0.0.5";
  config.sensor.multicast_ip = "239.1.1.1";
  config.sensor.data_port = 2370;
  config.latency.budget_ms = 7;
  const UdpReceiverOptions live = receiver_options(config, RunSource{});
  CHECK(live.host_ip == "10.0.0.5");
  CHECK(live.multicast_ip == "239.1.1.1");
  CHECK(live.port == 2370);
  CHECK(live.latency_budget_ns == 7'000'000);
  // A 40P in dual return (the model "auto" starts as): what sizes the packet ring's blocks.
  // (a firing every 55.56 µs: 3599.7 packets a second).
  CHECK(static_cast<double>(live.expected_bytes_per_second) ==
        Approx(3600.0 * (1266 + 42)).epsilon(0.001));
  RunSource simulated;
  simulated.kind = RunSource::Kind::kSimulated;
  UdpReceiverOptions sim = receiver_options(config, simulated);
  CHECK(sim.host_ip == "127.0.0.1");
  CHECK(sim.multicast_ip.empty());
  CHECK(sim.port == 0);
  simulated.port_given = true;
  CHECK(receiver_options(config, simulated).port == 2370);
  // A replay filters by port only when one was given.
  RunSource replay;
  replay.kind = RunSource::Kind::kReplay;
  replay.replay_path = "x.pcap";
  CHECK_FALSE(replay_options(config, replay).destination_port);
  replay.port_given = true;
  CHECK(replay_options(config, replay).destination_port == 2370);
}

// The packet ring's receiver copies a part of one kernel block at a time into the decoder's ring,
// emptied first: more slots than kPacketRingStagingSlots there only spread the copies over memory
// out of the cache. A replay and the socket receiver fill the ring from a thread of their own,
// and ring.slots is what they may queue.
TEST_CASE("the decoder's ring: ring.slots except where the packet ring stages its blocks",
          "[daemon][options]") {
  for (const std::uint32_t slots : {64u, 128u, 256u, 512u, 4096u, 1u << 20}) {
    for (const char* receiver : {"socket", "packet_ring"}) {
      for (const RunSource::Kind kind :
           {RunSource::Kind::kLive, RunSource::Kind::kSimulated, RunSource::Kind::kReplay}) {
        CAPTURE(slots, receiver, static_cast<int>(kind));
        DaemonConfig config;
        config.ring.slots = slots;
        config.input.receiver = receiver;
        RunSource source;
        source.kind = kind;
        const bool staged =
            std::string(receiver) == "packet_ring" && kind != RunSource::Kind::kReplay;
        CHECK(ring_slots(config, source) ==
              (staged ? std::min(slots, kPacketRingStagingSlots) : slots));
      }
    }
  }
  CHECK(kPacketRingStagingSlots == 256);
}

TEST_CASE("pipeline threads stop and join in the reverse of their start, also on a throw",
          "[daemon][threads]") {
  std::mutex mutex;
  std::vector<std::string> events;
  const auto note = [&](std::string event) {
    const std::lock_guard lock(mutex);
    events.push_back(std::move(event));
  };
  std::atomic<bool> stop_a{false}, stop_b{false};
  try {
    PipelineThreads threads;
    threads.start(
        "t-a", {},
        [&] {
          while (!stop_a.load())
            std::this_thread::yield();
          note("a ended");
        },
        [&] {
          note("stop a");
          stop_a = true;
        });
    threads.start(
        "t-b", {},
        [&] {
          while (!stop_b.load())
            std::this_thread::yield();
          note("b ended");
        },
        [&] {
          note("stop b");
          stop_b = true;
        });
    throw std::runtime_error("a start-up step failed");  // between start and the planned stop
  } catch (const std::runtime_error&) {
    // Every thread was joined before the catch: nothing more will be noted.
    const std::lock_guard lock(mutex);
    CHECK(events == std::vector<std::string>{"stop b", "b ended", "stop a", "a ended"});
  }
}

TEST_CASE("a pipeline thread is named and placed before its start returns", "[daemon][threads]") {
  std::atomic<bool> placed{false}, stop{false};
  PipelineThreads threads;
  threads.start(
      "t-placed", [&] { placed = true; },
      [&] {
        while (!stop.load())
          std::this_thread::yield();
      },
      [&] { stop = true; });
  CHECK(placed.load());  // no wait here: start() itself waited for the setup
  threads.stop_all();
  threads.stop_all();  // idempotent
}

// What a 40P sends in dual return, and the waits the defaults' bounds allow: a quarter of the
// arenas' frames (4 x 360 packets) with points decoded, a quarter of the raw batches (4 x 512)
// for a recording alone; a quarter of the 1 s no_data timeout is longer than either.
constexpr double k40PDualPps = 3599.7;
constexpr double kFramesBoundMs = 4 * 360 / 4 / k40PDualPps * 1000;     // 100.0 ms
constexpr double kRecordingBoundMs = 4 * 512 / 4 / k40PDualPps * 1000;  // 142.2 ms
// The packet ring's retire timer: whole milliseconds, 1 to 100.
double ring_wait_ms(double ms) {
  return std::clamp(std::floor(ms), 1.0, 100.0);
}

TEST_CASE("the latency budget is the frames': a recording alone wakes at its own flush period",
          "[daemon][options]") {
  const auto wait_ms = [](const DaemonConfig& config) {
    return static_cast<double>(receiver_options(config, RunSource{}).latency_budget_ns) / 1e6;
  };
  for (const std::uint32_t budget_ms : {0u, 5u, 50u, 100u, 400u, 1000u}) {
    DaemonConfig config;
    config.input.receiver = "packet_ring";
    config.latency.budget_ms = budget_ms;
    const double budget = budget_ms;
    INFO("budget " << budget_ms << " ms");
    // Anything that waits for frames keeps the budget as configured, up to what a quarter of the
    // arenas' frames take to arrive (a longer wait hands on more frames than there are arenas).
    // 0 (a wake per datagram) is kept as asked.
    const auto ring = [&](double ms) { return budget_ms == 0 ? 0.0 : ring_wait_ms(ms); };
    CHECK(wait_ms(config) == Approx(ring(std::min(budget, kFramesBoundMs))).epsilon(0.001));
    config.output.frames = false;
    config.output.mcap = true;
    CHECK(wait_ms(config) == Approx(ring(std::min(budget, kFramesBoundMs))).epsilon(0.001));
    config.output.mcap = false;
    config.live.foxglove = true;
    CHECK(wait_ms(config) == Approx(ring(std::min(budget, kFramesBoundMs))).epsilon(0.001));
    // Nothing does: the decoder's flush of the recording (100 ms) is the shortest wait that
    // buys anything; a longer budget stays up to the raw batches' bound and the ring's 100 ms.
    config.live.foxglove = false;
    CHECK(wait_ms(config) ==
          Approx(ring(std::min(std::max(budget, 100.0), kRecordingBoundMs))).epsilon(0.001));
    // The socket keeps the budget: it cannot wake on a burst as a full block does.
    config.input.receiver = "socket";
    CHECK(wait_ms(config) == Approx(std::min(budget, kRecordingBoundMs)).epsilon(0.001));
  }
}

TEST_CASE("no budget waits longer than a quarter of the no_data timeout, with either receiver",
          "[daemon][options]") {
  // budget_ms = 1000 with no_data_timeout_seconds = 0.3 said no_data while the sensor sent: the
  // receive thread held the packets longer than the silence health calls one.
  const auto wait_ms = [](const DaemonConfig& config) {
    return static_cast<double>(receiver_options(config, RunSource{}).latency_budget_ns) / 1e6;
  };
  for (const char* receiver : {"socket", "packet_ring"}) {
    for (const bool frames : {true, false}) {
      for (const double timeout : {0.004, 0.02, 0.1, 0.3, 1.0, 10.0}) {
        for (const std::uint32_t budget_ms : {1u, 5u, 100u, 1000u}) {
          DaemonConfig config;
          config.input.receiver = receiver;
          config.output.frames = frames;
          config.ring.slots = 65536;  // the ring and the raw batches hold seconds
          config.arenas.count = 64;
          config.arenas.packets_per_frame = 4096;
          config.health.no_data_timeout_seconds = timeout;
          config.latency.budget_ms = budget_ms;
          CAPTURE(receiver, frames, timeout, budget_ms);
          const double wait = wait_ms(config);
          CHECK(wait <= std::max(timeout / 4 * 1000, 1.0) + 0.001);
          CHECK(wait >= 1.0);  // never a wake per datagram unless 0 asks for it
          // No shorter than asked for, unless the timeout or the recording's flush says so.
          const bool packet_ring = std::string(receiver) == "packet_ring";
          const bool recording_ring = !frames && packet_ring;
          double expected =
              std::max(std::min(recording_ring ? std::max<double>(budget_ms, 100) : budget_ms,
                                timeout / 4 * 1000),
                       1.0);
          if (packet_ring) expected = ring_wait_ms(expected);
          CHECK(wait == Approx(expected).epsilon(0.001));
        }
      }
    }
  }
}

TEST_CASE("a recording alone waits no longer than a quarter of what its pipeline holds",
          "[daemon][options]") {
  const auto wait_ms = [](const DaemonConfig& config) {
    return static_cast<double>(receiver_options(config, RunSource{}).latency_budget_ns) / 1e6;
  };
  DaemonConfig config;
  config.input.receiver = "packet_ring";
  config.output.frames = false;
  REQUIRE(wait_ms(config) == 100);  // the defaults hold 284 ms (ring), 142 ms (raw), 250 ms
  // Each bound alone, at a 40P's 3600 packets a second in dual return.
  DaemonConfig ring = config;
  ring.ring.slots = 256;  // 71 ms of packets: a quarter is 17.8 ms
  CHECK(wait_ms(ring) == ring_wait_ms(256.0 / 3599.7 / 4 * 1000));
  DaemonConfig raw = config;
  raw.arenas.count = 2;
  raw.arenas.packets_per_frame = 128;
  CHECK(wait_ms(raw) == ring_wait_ms(256.0 / 3599.7 / 4 * 1000));
  raw.output.pcap = false;  // health only: no raw batches to fill
  CHECK(wait_ms(raw) == 100);
  DaemonConfig silence = config;
  silence.health.no_data_timeout_seconds = 0.1;
  CHECK(wait_ms(silence) == Approx(25).epsilon(0.01));
  // A configured budget longer than the bounds is held to them too (a longer wait fakes the
  // silence, or hands on more than the pipeline holds).
  silence.latency.budget_ms = 60;
  CHECK(wait_ms(silence) == Approx(25).epsilon(0.01));
  DaemonConfig small_ring = ring;
  small_ring.latency.budget_ms = 60;
  CHECK(wait_ms(small_ring) == ring_wait_ms(256.0 / 3599.7 / 4 * 1000));
  // A faster model fills the same slots sooner: a QT128 sends 9000 packets a second.
  RunSource qt;
  qt.model = SensorModelId::kPandarQT128;
  CHECK(static_cast<double>(receiver_options(ring, qt).latency_budget_ns) / 1e6 ==
        ring_wait_ms(256.0 / 9000 / 4 * 1000));
}

TEST_CASE("a wake hands on at most a quarter of what the ring, the raw batches and the arenas hold",
          "[daemon][options]") {
  DaemonConfig config;  // 4096 slots, 4 x 512 raw packets, 4 arenas of a 40P's 360 packets
  const auto wake = [&] { return receiver_options(config, RunSource{}).max_wake_datagrams; };
  CHECK(wake() == 4 * 360 / 4);
  config.arenas.count = 8;  // 8 x 360 = 2880: the raw batches (8 x 512) and the ring hold more
  CHECK(wake() == 8 * 360 / 4);
  config.output.frames = false;  // no points decoded: the ring and raw batches alone
  CHECK(wake() == 4096 / 4);
  config.arenas.count = 4;
  CHECK(wake() == 2048 / 4);
  config.output.pcap = false;  // no raw batches: the ring alone
  CHECK(wake() == 4096 / 4);
  config.output.mcap = true;  // MCAP decodes points: the arenas' frames again
  CHECK(wake() == 4 * 360 / 4);
  config.output.mcap_packets = true;  // and takes raw batches
  config.arenas.packets_per_frame = 64;
  CHECK(wake() == 4 * 64 / 4);
  config.arenas.packets_per_frame = 512;
  config.ring.slots = 256;
  CHECK(wake() == 256 / 4);
  config.ring.slots = 2;
  CHECK(wake() == 1);
  // A faster model's frames hold more packets: a QT128 at 600 RPM sends 900 a revolution (no
  // pcap, whose raw batches would hold fewer).
  DaemonConfig qt_config;
  qt_config.output.pcap = false;
  RunSource qt;
  qt.model = SensorModelId::kPandarQT128;
  CHECK(receiver_options(qt_config, qt).max_wake_datagrams == Approx(4 * 900 / 4).margin(1));
}

TEST_CASE("the packet ring's expected rate follows the configured model", "[daemon][options]") {
  DaemonConfig config;
  RunSource source;
  source.model = SensorModelId::kPandarQT128;
  const std::uint64_t qt = receiver_options(config, source).expected_bytes_per_second;
  source.model = SensorModelId::kPandar40P;
  const std::uint64_t p40 = receiver_options(config, source).expected_bytes_per_second;
  CHECK(static_cast<double>(p40) == Approx(3600.0 * (1266 + 42)).epsilon(0.001));
  // The QT128 sends 9000 packets a second in dual return, each smaller than a 40P's.
  CHECK(qt > p40);
  CHECK(qt < 9000 * (1266 + 42));
}
