// pandarcapd: the Pandar40P capture daemon.
//
//   receive thread (recvmmsg) or replay --ring--> decode worker --queue--> writer thread
//   (input.receiver = "packet_ring": the kernel's ring of blocks --> decode worker, which reads
//   it itself; no receive thread)
//   main thread: signals, sd_notify READY/STATUS/WATCHDOG/STOPPING, --duration, shutdown order
//
// Start-up, in dependency order (shutdown is the reverse):
//   1. options and configuration (bad config: the file:line:col message and exit 78)
//   2. logging, the sensor: calibration (sensor.calibration_source), identity, configuration
//   3. memory: ring, frame arenas, raw batches, queues — all of it, once
//   4. outputs prepared (directories writable) and the source opened (socket bound / file open)
//   5. threads started, READY=1
// Each step is a function of startup_steps.hpp; the command line is pandarcapd_command_line.hpp,
// its --help text pandarcapd_usage.hpp.
// Exit status: 0 done, 1 runtime failure, 64 usage, 65 a replayed recording is damaged or cut
// short (what could be read was replayed), 66 capture unreadable, 69 the sensor did not
// give its calibration (calibration_source = "sensor"), 73 outputs cannot be created, 78
// configuration (or calibration file) invalid.
#include <fmt/format.h>
#include <pthread.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <iterator>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "config/config_loader.hpp"
#include "config/daemon_config.hpp"
#include "core/health/health_state_log.hpp"
#include "core/log_text.hpp"
#include "core/progress_line.hpp"
#include "daemon/clocks.hpp"
#include "daemon/daemon_options.hpp"
#include "daemon/decode_worker.hpp"
#include "daemon/live/foxglove_server.hpp"
#include "daemon/live/live_handover.hpp"
#include "daemon/live/live_port_probe.hpp"
#include "daemon/output/stall_report.hpp"
#include "daemon/output/writer.hpp"
#include "daemon/output/writer_stall_watch.hpp"
#include "daemon/packet_slot.hpp"
#include "daemon/pandarcapd_command_line.hpp"
#include "daemon/pipeline.hpp"
#include "daemon/pipeline_types.hpp"
#include "daemon/ptc/sensor_status_poller.hpp"
#include "daemon/sd_notify.hpp"
#include "daemon/source/packet_source.hpp"
#include "daemon/startup_steps.hpp"
#include "daemon/thread_tuning.hpp"

namespace {

using namespace pandarcap;

constexpr std::string_view kVersion = PANDARCAP_VERSION;

// From the writer's final health in memory, not from health.jsonl: when the disk is full the
// file's last line is an older one, and the summary must say how the run really ended.
void print_summary(const WriterOptions& wo, const HealthSnapshot& h) {
  // Configured paths, escaped: a control character in one cannot forge a line.
  const auto shown = [](const std::filesystem::path& path) {
    return escaped_control(path.native());
  };
  const std::filesystem::path& dir = wo.output_dir;
  fmt::print("outputs in {}:\n", shown(dir));
  if (wo.frames) fmt::print("  frames  {}\n", shown(dir / "frames"));
  if (wo.pcap) fmt::print("  raw     {}\n", shown(dir / "raw"));
  if (wo.mcap) fmt::print("  mcap    {}\n", shown(dir / "mcap"));
  fmt::print("  health  {} and {}\n", shown(wo.prometheus_file),
             shown(wo.health_dir / "health.jsonl"));
  const HealthCounters& c = h.counters;
  fmt::print(
      "final health: state {}{}; {} datagrams received, {} accepted, {} rejected, {} foreign, "
      "{} ring overruns, {} kernel drops; frames {} complete, {} partial, {} dropped, {} "
      "fragments, {} written; {} packets recorded{}; {} write errors\n",
      to_string(h.gauges.state),
      h.gauges.reason.empty() ? "" : " (" + escaped_control(h.gauges.reason) + ")",
      c.datagrams_received, c.packets_accepted, c.packets_rejected, c.foreign_datagrams,
      c.ring_overruns, c.kernel_drops, c.frames_complete, c.frames_partial,
      c.frames_dropped_no_arena, c.frames_fragment, c.frames_written,
      // What is in the recordings on disk: written, less what vanished with its file.
      c.pcap_packets_written - c.pcap_packets_lost,
      c.packets_not_recorded > 0 ? fmt::format(" ({} not recorded)", c.packets_not_recorded)
                                 : std::string(),
      c.write_errors);
  if (c.duplicate_packets > 0 || c.outlier_packets > 0) {
    fmt::print(
        "{} duplicate packets (not decoded again), {} isolated outliers (placed at their azimuth's "
        "time, or left out), no frame cut for them\n",
        c.duplicate_packets, c.outlier_packets);
  }
  {
    // The stream's faults, those that occurred (issue 38's rules: docs/decoding.md).
    std::string faults;
    const auto add = [&](std::uint64_t n, const char* what) {
      if (n == 0) return;
      fmt::format_to(std::back_inserter(faults), "{}{} {}", faults.empty() ? "" : ", ", n, what);
    };
    add(c.points_missing, "points missing (lost packets; the frames that lost them are partial)");
    add(c.standing_packets, "standing packets (motor not turning; left out)");
    add(c.other_sensor_packets, "packets from a second sensor (dropped)");
    add(c.sequence_resets, "sequence resets");
    if (!faults.empty()) fmt::print("{}\n", faults);
  }
  if (wo.mcap) {
    fmt::print("mcap: {} messages written, {} not written, {} not recorded, {} bytes{}{}\n",
               c.mcap_messages_written - c.mcap_messages_lost, c.mcap_messages_not_written,
               c.mcap_messages_not_recorded, c.mcap_bytes_written,
               c.mcap_chunks_uncompressed > 0
                   ? fmt::format("; {} chunks stored uncompressed (compression behind)",
                                 c.mcap_chunks_uncompressed)
                   : std::string(),
               c.mcap_messages_lost > 0
                   ? fmt::format("; {} more lost with their file", c.mcap_messages_lost)
                   : std::string());
  }
  if (c.files_removed_for_space > 0) {
    // Removed on purpose, as retention's are: what they held was recorded (counted above), then
    // given up, oldest first, for the floor of free space.
    fmt::print(
        "free-space floor: {} of the oldest files ({} MiB, earlier runs' included) removed to keep "
        "the floor of free space\n",
        c.files_removed_for_space, c.bytes_removed_for_space >> 20);
  }
  if (c.files_removed_before_upload > 0) {
    fmt::print(
        "upload: {} files ({} MiB) removed by the floor or retention before they were uploaded\n",
        c.files_removed_before_upload, c.bytes_removed_before_upload >> 20);
  }
}

// The main thread while the pipeline runs: signals, --duration, the end of a replay, STATUS and
// WATCHDOG. Returns when the daemon should stop.
// A replay's progress on a terminal (daemon_options.hpp: replay_progress_wanted): a line on
// stderr, rewritten in place, for a replay that runs longer than a few seconds.
void show_progress(ProgressLine& progress, const ReplaySource& replay, const Pipeline& pipe,
                   double elapsed_s) {
  if (auto line = progress.update(elapsed_s, replay.bytes_read(), replay.size_bytes(),
                                  pipe.receive.datagrams.load(std::memory_order_relaxed))) {
    std::fprintf(stderr, "\r%s\x1b[K", line->c_str());  // over the last one, the rest cleared
  }
}

// `replay`: the replay whose progress to show, or null.
void supervise(Pipeline& pipe, const sigset_t& signals, std::optional<double> duration_s,
               const ReplaySource* replay, StalledWriterReport& stall) {
  const auto start = std::chrono::steady_clock::now();
  ProgressLine progress = replay_progress_line();
  // The progress line ends with the run, whichever way supervise() returns.
  struct EndLine {
    ProgressLine& progress;
    ~EndLine() {
      if (progress.shown()) std::fputc('\n', stderr);
    }
  } end_line{progress};
  const auto watchdog = systemd::watchdog_interval();
  // A replay's progress line and its end are looked at ten times a second. Live, what this
  // loop reports (state changes, a stalled writer, the watchdog) is judged in seconds: two
  // wake-ups a second are enough, and each costs the process some 30 µs on a VM.
  // A short WatchdogSec needs its pings (every half of it) on time: a quarter of it at most.
  auto tick = std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::milliseconds(replay != nullptr ? 100 : 500));
  if (watchdog) {
    tick =
        std::min(tick, std::max(std::chrono::duration_cast<std::chrono::nanoseconds>(*watchdog) / 4,
                                std::chrono::nanoseconds(1'000'000)));
  }
  auto next_watchdog = start;
  std::uint64_t seen[3] = {~0ull, ~0ull, ~0ull};
  HealthStateLog state_log;
  // The writer's heartbeat, and since when it stands: stuck on its disk for
  // WriterStallWatch::kStall, its health is reported from here (daemon/output/stall_report.hpp),
  // once a second.
  WriterStallWatch writer_watch(start, tick, pipe.heartbeats.writer.load());
  auto next_stall_report = start;
  for (;;) {
    auto wait = tick;
    if (duration_s) {  // a --duration ends on time, not at the next tick
      const auto left = std::chrono::duration_cast<std::chrono::nanoseconds>(
          std::chrono::duration<double>(*duration_s) - (std::chrono::steady_clock::now() - start));
      wait = std::clamp(left, std::chrono::nanoseconds(1'000'000), wait);
    }
    const timespec timeout{0, wait.count()};
    const int signal = sigtimedwait(&signals, nullptr, &timeout);
    if (signal == SIGTERM || signal == SIGINT) {
      spdlog::info("{}: stopping", signal == SIGTERM ? "SIGTERM" : "SIGINT");
      return;
    }
    if (signal == SIGHUP) pipe.rotate_generation.fetch_add(1, std::memory_order_relaxed);
    const auto now = std::chrono::steady_clock::now();  // one clock read a tick
    if (duration_s && now - start >= std::chrono::duration<double>(*duration_s)) {
      spdlog::info("{} s elapsed: stopping", *duration_s);
      return;
    }
    if (pipe.source_done.load(std::memory_order_acquire)) return;  // replay finished
    const double since_start = std::chrono::duration<double>(now - start).count();
    if (replay != nullptr) show_progress(progress, *replay, pipe, since_start);
    StatusLine status;
    while (pipe.status.try_pop(status)) {
      systemd::status(status.text);
      if (auto line = state_log.update(status.state, status.reason, since_start)) {
        if (line->warning) {
          spdlog::warn("{}", line->text);
        } else {
          spdlog::info("{}", line->text);
        }
      }
    }
    if (const auto stood = writer_watch.look(now, pipe.heartbeats.writer.load()); !stood) {
      if (stall.active()) stall.clear();
    } else if (now >= next_stall_report) {
      const double stalled = std::chrono::duration<double>(*stood).count();
      stall.write(stalled, std::chrono::duration_cast<std::chrono::nanoseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count());
      systemd::status(
          fmt::format("degraded: writer stalled for {:.0f} s (its disk does not answer)", stalled));
      next_stall_report = now + std::chrono::seconds(1);
    }
    if (watchdog && now >= next_watchdog) {
      // Only while all three loops are making progress (each bumps its counter even when idle).
      const std::uint64_t beats[3] = {pipe.heartbeats.receive.load(), pipe.heartbeats.decode.load(),
                                      pipe.heartbeats.writer.load()};
      if (beats[0] != seen[0] && beats[1] != seen[1] && beats[2] != seen[2]) {
        systemd::watchdog();
        std::copy(std::begin(beats), std::end(beats), std::begin(seen));
      }
      next_watchdog = now + *watchdog / 2;
    }
  }
}

// How a replay ended: kExitDataDamaged when the file is not whole (damaged, or cut short: every
// packet that could be read was replayed, and the summary, the log and the last health record
// name what was not), else 0.
int report_replay(const PacketSource& source, const RunSource& run_source) {
  if (!source.replayed()) return 0;
  const ReplayResult& result = source.replay_result();
  const auto& capture = result.capture;
  // In the exit summary, whatever it says: a record the replay could not use is never silent.
  fmt::print(
      "replay: {} records, {} UDP datagrams ({} IPv6), {} to other ports; {} skipped ({} not IP, "
      "{} not UDP, {} IP fragments, {} malformed)\n",
      capture.records, capture.udp_datagrams, capture.ipv6_datagrams, capture.port_filtered,
      capture.skipped(), capture.non_ip, capture.non_udp, capture.ip_fragments, capture.malformed);
  if (capture.chunks_skipped > 0 || capture.records_damaged > 0) {
    fmt::print(
        "replay: {} damaged MCAP chunks skipped ({} packets in them), {} damaged record lengths "
        "read over\n",
        capture.chunks_skipped, capture.packets_skipped, capture.records_damaged);
  }
  if (capture.skipped() > 0) {
    spdlog::warn(
        "{}: {} of {} records skipped: {} not IP, {} not UDP, {} IP fragments (not reassembled), "
        "{} malformed",
        run_source.replay_path, capture.skipped(), capture.records, capture.non_ip, capture.non_udp,
        capture.ip_fragments, capture.malformed);
  }
  // The reader's texts name the file already.
  if (!result.first_damage.empty()) spdlog::error("damaged: {}", result.first_damage);
  const bool damaged = !result.first_damage.empty() || capture.malformed > 0;
  if (result.status == CaptureStatus::kTruncated) {
    spdlog::error("cut short: {}", result.error);
  } else if (result.status == CaptureStatus::kError) {
    spdlog::error("damaged: {}", result.error);
  } else if (!damaged) {
    return 0;
  }
  fmt::print("replay: {} is {}: exit status {}\n", run_source.replay_path,
             result.status == CaptureStatus::kTruncated ? "cut short" : "damaged",
             kExitDataDamaged);
  return kExitDataDamaged;
}

// The daemon's life, in order; shutdown is the reverse (PipelineThreads).
int run(const CommandLine& command_line) {
  CommandLine options = command_line;  // the start fills in the sensor model
  // A stop asked for from here on ends the start within a second, at whatever step it is.
  take_signals_for_startup();
  const std::string source_name = options.config_path.value_or("command line");
  const DaemonConfig config = load_configuration(options, source_name);
  if (options.check_config) return check_config(config, source_name);
  if (options.print_config) {
    fmt::print("{}", to_toml(config));
    return 0;
  }

  setup_logging(config.log_level);
  if (!options.print_calibration) {
    spdlog::info("pandarcapd {} starting ({})", kVersion, describe(options.source));
  }
  std::unique_ptr<SimulatedPtcServer> simulated_ptc;  // outlives every thread that asks it
  std::optional<PtcClientOptions> ptc;
  choose_sensor_model(config, options.source);
  SensorAtStart sensor = learn_sensor(config, options.source, simulated_ptc, ptc);
  sensor.model = options.source.model;  // for sensor.json
  stop_if_requested("asking the sensor");
  const Calibration& calibration = sensor.calibration;
  if (options.print_calibration) {
    fmt::print("{}", calibration.to_csv());
    return 0;
  }
  refuse_root_unless_allowed(options, config);
  log_sensor(sensor, config, options.source);
  const DecoderTarget decoder = choose_decoder(config);

  // All the memory, now: arenas sized for the model (every model's when the packets choose it).
  const std::uint32_t points_per_arena = arena_points(config, options.source.model);
  const std::uint32_t slots = ring_slots(config, options.source);
  Pipeline pipe(config, points_per_arena, slots);
  spdlog::info(
      "memory: ring {} slots x {} B{}, {} frame arenas x {} points, {} raw batches x {} "
      "packets",
      slots, sizeof(PacketSlot),
      slots < config.ring.slots ? " (the packet ring's blocks staged there)" : "",
      config.arenas.count, points_per_arena, Pipeline::raw_batches(config),
      config.arenas.packets_per_frame);
  stop_if_requested("allocating memory");

  const std::unique_ptr<PacketSource> source = open_source(config, options.source);
  WriterOptions wo = writer_options(config, options.source.model);
  wo.decoder = std::string(to_string(decoder));
  wo.calibration_csv = calibration.to_csv();
  wo.calibration_model = calibration.model();
  if (options.source.detect_model) {
    // The packets may name another model: each one's table is ready (the given one for its
    // model, the nominal one for the others), as the decoder's is (DecodeWorker::choose_model).
    for (const SensorModelId id : kSensorModelIds) {
      wo.calibration_by_model[static_cast<std::size_t>(id)] =
          id == calibration.model() ? wo.calibration_csv : Calibration::nominal(id).to_csv();
    }
  }
  // A nominal table is the model's own whatever the packets say (the decoder takes that model's).
  wo.calibration_channels = sensor.calibration_source == "nominal" ? 0 : calibration.channel_count;
  wo.inventory_lasers = sensor.inventory ? sensor.inventory->lines : 0;
  wo.sensor_identity = SensorIdentity{sensor.inventory ? sensor.inventory->serial : "",
                                      sensor.inventory ? sensor.inventory->sensor_firmware : "",
                                      sensor.calibration_source};
  wo.sensor_json = sensor.to_json(wo.device_name, wo.config_hash);
  wo.status_polled = status_polled(config, options.source, ptc);
  wo.status_interval_seconds = config.sensor.status_interval_seconds;
  pipe.sensor_status.requests.store(sensor.ptc_requests);
  pipe.sensor_status.errors.store(sensor.ptc_errors);
  wo.mcap_replay_time = options.source.kind == RunSource::Kind::kReplay;
  // A replay (a conversion) is written whole: the writer waits for a chunk buffer rather than
  // leave a message out; live, nothing may wait on the compression thread.
  wo.mcap_file.wait_for_free_chunk = wo.mcap_replay_time;
  const auto lock = claim_outputs(config.output.directory);
  Writer writer(wo, pipe.to_writer, pipe.free_arenas, pipe.free_raw, pipe.receive, pipe.live,
                pipe.sensor_status);
  // The live view: its memory and its listening socket now, before READY=1.
  std::unique_ptr<live::LiveHandover> live_handover;
  std::unique_ptr<live::FoxgloveServer> live_server;
  if (config.live.foxglove) {
    live_handover =
        std::make_unique<live::LiveHandover>(live_points_capacity(config, options.source.model));
    try {
      live_server = std::make_unique<live::FoxgloveServer>(
          live_options(config, kVersion, options.source.model), *live_handover);
    } catch (const std::exception& error) {
      throw StartupError{1, error.what()};  // as a data port in use is
    }
    writer.attach_live(*live_handover);
    // Bound: another program's IPv6 socket on the same port would still catch a viewer that
    // opens ws://localhost (not bound: the server has said so and tries again).
    if (live_server->port() != 0 && live::ipv6_loopback_port_taken(live_server->port())) {
      spdlog::warn(
          "live view: port {} is held on IPv6 (::1) by another program: a viewer that opens "
          "ws://localhost:{} may reach that one; open ws://{}:{}",
          live_server->port(), live_server->port(), config.live.address, live_server->port());
    }
  }
  try {
    writer.prepare();
  } catch (const std::bad_alloc&) {
    // Not the output directory's fault (kExitCantCreate would say so): the frames' buffers.
    throw StartupError{
        1, fmt::format("outputs: the writer's buffers for frames of {} points (arenas."
                       "points_per_frame, at least a revolution of the model; output.pcd_"
                       "compression, output.mcap) do not fit: cannot allocate them",
                       points_per_arena)};
  } catch (const std::exception& error) {
    throw StartupError{kExitCantCreate, fmt::format("outputs: {}", error.what())};
  }
  DecodeWorker worker(calibration,
                      decode_worker_options(config, decoder, options.source, calibration.model()),
                      pipe.ring, pipe.to_writer, pipe.free_arenas, pipe.free_raw);
  // From here the signals are supervise()'s: blocked before the first pipeline thread starts,
  // so every thread inherits the mask (a SIGTERM taken by another thread would be lost to it).
  const sigset_t signals = block_signals();
  stop_if_requested("preparing the outputs");

  const ThreadsSection& placement = config.threads;
  std::atomic<bool> stop_simulator{false};
  // Declared before the threads: it outlives them.
  std::optional<SensorStatusPoller> status_poller;
  PipelineThreads threads;
  // The status poller starts first so that it stops last (stop_all: the last started first):
  // it keeps asking while the decoder drains the ring and the writer finishes its files, and
  // the final health record has a status as fresh as any other second's, not one aged by
  // the shutdown.
  if (wo.status_polled) {
    const auto interval = std::chrono::milliseconds(
        static_cast<std::int64_t>(config.sensor.status_interval_seconds * 1000));
    status_poller.emplace(
        *ptc, interval, pipe.sensor_status,
        sensor.settings ? std::optional(sensor.settings->clock_source) : std::nullopt);
    spdlog::info("sensor status: asking {}:{} every {} s", ptc->address, ptc->port,
                 config.sensor.status_interval_seconds);
    threads.start(
        "pc-sensorstat", {}, [&] { status_poller->run(); }, [&] { status_poller->stop(); });
  }
  bool decoder_started = false;
  // From now on a live receiver is listening, before its thread's first look: a writer that
  // finds no look by its first record holds it, and then says the receiver is behind.
  if (!source->replayed()) pipe.receive.listening_since_monotonic_ns.store(monotonic_ns());
  try {
    threads.start(
        "pc-writer",
        [&] {
          place_this_thread("writer", {placement.writer_cpu, placement.writer_priority});
        },
        [&] { writer.run(pipe.heartbeats.writer, pipe.rotate_generation, pipe.status); });
    if (live_server) {
      threads.start(
          "pc-live", {}, [&] { live_server->run(); }, [&] { live_server->stop(); });
    }
    const auto stop_source = [&] { pipe.stop_source.store(true, std::memory_order_relaxed); };
    if (source->read_by_decoder()) {
      // The packet ring: the decode thread reads it (PacketSource::read_by_decoder), and a stop
      // is asked of it. No receive thread to place.
      if (placement.receive_cpu != -1 || placement.receive_priority != 0) {
        spdlog::warn(
            "threads.receive_cpu and receive_priority are not used with input.receiver = "
            "\"packet_ring\": the decode thread reads the ring (threads.decode_cpu and "
            "decode_priority place it)");
      }
      const DecodeWorker::ReceiveInline receive = [&](PacketRing& ring) {
        return source->receive_turn(ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive,
                                    pipe.source_done);
      };
      // After a stop what arrives no longer matters: what was taken waits for the writer (its
      // drain's deadline counts what it leaves in the kernel's ring).
      // Half the kernel's ring and no less than kLeastWaitRoomBlocks stay free while the
      // decoder waits.
      const DecodeWorker::UpstreamRoom room = [&] {
        source->note_arrivals(pipe.receive);  // the health's last packet, while the decoder waits
        const std::uint32_t waiting = source->blocks_waiting();
        const std::uint32_t blocks = source->block_count();
        return DecodeWorker::Upstream{
            waiting < blocks && DecodeWorker::room_to_wait(blocks - waiting, blocks,
                                                           DecodeWorker::kLeastWaitRoomBlocks),
            pipe.stop_source.load(std::memory_order_relaxed)};
      };
      threads.start(
          "pc-decode",
          [&] {
            place_this_thread("decode", {placement.decode_cpu, placement.decode_priority});
          },
          [&, receive, room] {
            worker.run_inline(receive, room, pipe.heartbeats.decode, pipe.live);
          },
          stop_source);
      decoder_started = true;
    } else {
      threads.start(
          "pc-decode",
          [&] {
            place_this_thread("decode", {placement.decode_cpu, placement.decode_priority});
          },
          [&] { worker.run(pipe.source_done, pipe.heartbeats.decode, pipe.live); });
      decoder_started = true;
      threads.start(
          source->thread_name(),
          [&] {
            place_this_thread("receive", {placement.receive_cpu, placement.receive_priority});
          },
          [&] {
            source->run(pipe.ring, pipe.stop_source, pipe.receive, pipe.heartbeats.receive,
                        pipe.source_done);
          },
          stop_source);
    }
    if (source->simulated()) {
      threads.start(
          "pc-simsensor", {}, [&] { source->run_simulator(stop_simulator); },
          [&] { stop_simulator.store(true, std::memory_order_relaxed); });
    }
  } catch (const std::system_error& error) {
    // No receiver may be listening: the final record is not to say it fell behind.
    pipe.receive.note_stop(monotonic_ns());
    // The threads that did start end when their input does: the decoder's is the source's end,
    // the writer's the decoder's. One that never started cannot give it, so it is given here
    // (the writer's queue has no other producer until the decoder runs), and stop_all() joins.
    if (decoder_started) {
      pipe.source_done.store(true, std::memory_order_release);
    } else {
      WriterMessage end;
      end.kind = WriterMessage::Kind::kEnd;
      (void)pipe.to_writer.try_push(end);
    }
    threads.stop_all();
    throw std::runtime_error(fmt::format(
        "{} (a stack or thread limit: ulimit -s / -u, systemd's LimitSTACK= / TasksMax=)",
        error.what()));
  }
  if (config.threads.lock_memory) lock_all_memory();
  systemd::ready();
  spdlog::info("ready: writing to {}", config.output.directory);

  StalledWriterReport stall(wo);
  supervise(pipe, signals, options.duration_s,
            replay_progress_wanted() ? source->replay_source() : nullptr, stall);

  systemd::stopping();
  threads.stop_all();  // the decoder drains the ring, the writer finishes every file
  const int status = report_replay(*source, options.source);
  print_summary(wo, writer.final_health());
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  // A file-size limit (systemd's LimitFSIZE=, ulimit -f) must fail the one write with EFBIG,
  // counted like a full disk, not kill the daemon with SIGXFSZ.
  std::signal(SIGXFSZ, SIG_IGN);
  const CommandLine options = parse_command_line(argc, argv);
  try {
    return run(options);
  } catch (const StartupError& error) {
    // Before logging is set up (the configuration), plain stderr; after it, the log.
    if (spdlog::get("pandarcapd") != nullptr) {
      if (error.exit_status == 0) {
        spdlog::info("{}", error.message);  // a stop asked for during the start
      } else {
        spdlog::critical("{}", error.message);
      }
    } else {
      const std::string text = error.lines ? error.message : escaped_control(error.message);
      std::fprintf(stderr, "pandarcapd: %s\n", text.c_str());
    }
    return error.exit_status;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "pandarcapd: %s\n", escaped_control(error.what()).c_str());
    return 1;
  }
}
