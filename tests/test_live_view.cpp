// The live view (daemon/live/): the hand-over's newest-wins slot, the client requests parsed
// from untrusted text, the [live] keys, and pandarcapd serving Foxglove's own client
// (tests/foxglove_client: @foxglove/ws-protocol and Foxglove's ROS 2 CDR reader), a viewer that
// never reads, connection churn, garbage and oversize client frames, and more viewers than
// live.max_clients, all on 127.0.0.1.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "bench/child_process.hpp"
#include "config/config_loader.hpp"
#include "core/sensors/packet.hpp"
#include "daemon/live/foxglove_protocol.hpp"
#include "daemon/live/latest_message.hpp"
#include "support/test_support.hpp"

namespace fs = std::filesystem;
using nlohmann::json;
using pandarcap::live::ClientRequest;
using pandarcap::live::parse_client_request;
using namespace std::chrono_literals;

namespace {

using namespace pandarcap;

// A TCP port on 127.0.0.1 that was free a moment ago.
std::uint16_t free_tcp_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

fs::path client_dir() {
  return fs::path(PANDARCAP_SOURCE_DIR) / "tests" / "foxglove_client";
}

// Whether Foxglove's client is installed; under CI=true it must be.
bool client_installed() {
  if (fs::exists(client_dir() / "node_modules" / "@foxglove" / "ws-protocol") &&
      test::run_command("command -v node >/dev/null 2>&1").exit_code == 0) {
    return true;
  }
  const char* ci = std::getenv("CI");
  if (ci != nullptr && std::string(ci) == "true") {
    FAIL("Foxglove's client is not installed under CI=true (.ci/install-deps runs npm ci in "
         << client_dir().string() << ")");
  }
  WARN("Foxglove's client not installed (npm ci in " << client_dir().string() << "): not run");
  return false;
}

// pandarcapd --simulate for `duration_s` with the live view on a free port (and `config_text`
// as its configuration file), started and ready.
struct LiveRun {
  LiveRun(const std::string& tag, double duration_s, const std::string& config_text = "")
      : dir(tag), port(free_tcp_port()), daemon(start(duration_s, config_text)) {
    REQUIRE(
        harness::wait_until([&] { return daemon.log().find("ready:") != std::string::npos; }, 20s));
  }
  std::string url() const { return "ws://127.0.0.1:" + std::to_string(port); }
  // Seconds since the daemon was started.
  double seconds_running() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  }
  // Foxglove's client watching `clouds` frames (live_client.mjs watch): its JSON report.
  test::CommandResult watch(int clouds) const {
    return test::run_command("node '" + (client_dir() / "live_client.mjs").string() + "' watch " +
                             url() + " '" + (dir / "out" / "frames").string() + "' " +
                             std::to_string(clouds) + " 2>&1");
  }

  test::ScratchDir dir;
  std::uint16_t port;
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();
  harness::ChildProcess daemon;

 private:
  harness::ChildProcess start(double duration_s, const std::string& config_text) const {
    std::vector<std::string> args{
        "--allow-root",    "--simulate",         "--duration",   std::to_string(duration_s),
        "--foxglove-port", std::to_string(port), "--output-dir", (dir / "out").string()};
    if (!config_text.empty()) {
      std::ofstream(dir / "live.toml") << config_text;
      args.insert(args.begin(), {"-c", (dir / "live.toml").string()});
    }
    return harness::ChildProcess(test::binary("pandarcapd"), args, dir / "daemon.log");
  }
};

// A raw WebSocket client, to send what Foxglove's client never would.
class RawClient {
 public:
  explicit RawClient(std::uint16_t port) : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  ~RawClient() { ::close(fd_); }
  RawClient(const RawClient&) = delete;
  RawClient& operator=(const RawClient&) = delete;

  // Sends the opening handshake (with `protocol`, if any) and returns the response's status line.
  std::string handshake(const std::string& protocol = std::string(pandarcap::live::kSubprotocol)) {
    std::string request =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n";
    if (!protocol.empty()) request += "Sec-WebSocket-Protocol: " + protocol + "\r\n";
    return raw_request(request + "\r\n");
  }
  std::string raw_request(const std::string& request) {
    if (!connected_) return "no connection";
    send_all(request);
    std::string response;
    char c = 0;
    while (response.find("\r\n\r\n") == std::string::npos && read_some(&c, 1, 5000))
      response += c;
    return response.substr(0, response.find("\r\n"));
  }
  // A frame from the client: masked unless told otherwise.
  void send_frame(std::uint8_t first_byte, const std::string& payload, bool masked = true) {
    std::string f(1, static_cast<char>(first_byte));
    const std::uint8_t mask_bit = masked ? 0x80 : 0;
    if (payload.size() < 126) {
      f += static_cast<char>(mask_bit | payload.size());
    } else if (payload.size() < 65536) {
      f += static_cast<char>(mask_bit | 126);
      f += static_cast<char>(payload.size() >> 8);
      f += static_cast<char>(payload.size() & 0xFF);
    } else {
      f += static_cast<char>(mask_bit | 127);
      for (int i = 7; i >= 0; --i)
        f += static_cast<char>((payload.size() >> (8 * i)) & 0xFF);
    }
    const char key[4] = {0x12, 0x34, 0x56, 0x78};
    if (masked) f.append(key, 4);
    for (std::size_t i = 0; i < payload.size(); ++i)
      f += masked ? static_cast<char>(payload[i] ^ key[i % 4]) : payload[i];
    send_all(f);
  }
  // The next frame from the server: its opcode and payload; opcode -1 when the connection ended
  // (or nothing came within 5 s).
  std::pair<int, std::string> read_frame() {
    std::uint8_t h[2];
    if (!read_some(h, 2, 5000)) return {-1, ""};
    std::uint64_t n = h[1] & 0x7F;
    if (n >= 126) {
      std::uint8_t ext[8];
      const int bytes = n == 126 ? 2 : 8;
      if (!read_some(ext, bytes, 5000)) return {-1, ""};
      n = 0;
      for (int i = 0; i < bytes; ++i)
        n = (n << 8) | ext[i];
    }
    std::string payload(n, '\0');
    if (n > 0 && !read_some(payload.data(), n, 5000)) return {-1, ""};
    return {h[0] & 0x0F, payload};
  }
  // The server's frames until one whose text holds `needle`, or the end (false).
  bool read_until(const std::string& needle) {
    for (int i = 0; i < 50; ++i) {
      const auto [op, payload] = read_frame();
      if (op < 0) return false;
      if (payload.find(needle) != std::string::npos) return true;
    }
    return false;
  }
  // Whether the server closed: a close frame (its code in `code`) or the connection's end.
  bool closed_by_server(int& code) {
    for (int i = 0; i < 50; ++i) {
      const auto [op, payload] = read_frame();
      if (op < 0) return true;
      if (op == 8) {
        code = payload.size() >= 2 ? (static_cast<std::uint8_t>(payload[0]) << 8) |
                                         static_cast<std::uint8_t>(payload[1])
                                   : 0;
        return true;
      }
    }
    return false;
  }

 private:
  void send_all(const std::string& bytes) {
    std::size_t at = 0;
    while (at < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + at, bytes.size() - at, MSG_NOSIGNAL);
      if (n <= 0) return;
      at += static_cast<std::size_t>(n);
    }
  }
  bool read_some(void* out, std::size_t n, int timeout_ms) {
    auto* p = static_cast<char*>(out);
    while (n > 0) {
      pollfd pfd{fd_, POLLIN, 0};
      if (::poll(&pfd, 1, timeout_ms) <= 0) return false;
      const ssize_t got = ::recv(fd_, p, n, 0);
      if (got <= 0) return false;
      p += got;
      n -= static_cast<std::size_t>(got);
    }
    return true;
  }
  int fd_;
  bool connected_ = false;
};

}  // namespace

TEST_CASE("the live hand-over keeps the newest message and says when it replaced one", "[live]") {
  live::LatestMessage slot(64);
  CHECK(slot.take() == nullptr);
  slot.back().assign({1, 2, 3});
  CHECK_FALSE(slot.publish());
  slot.back().assign({4, 5});
  CHECK(slot.publish());  // {1,2,3} was never taken
  const std::vector<std::uint8_t>* m = slot.take();
  REQUIRE(m != nullptr);
  CHECK(*m == std::vector<std::uint8_t>{4, 5});
  CHECK(slot.take() == nullptr);
  // Three buffers, none given to both sides: the producer's next one is not the taken one.
  CHECK(&slot.back() != m);
  slot.back().assign({6});
  CHECK_FALSE(slot.publish());
  CHECK(*slot.take() == std::vector<std::uint8_t>{6});
  CHECK(slot.back().capacity() >= 64);
}

TEST_CASE("client requests: subscribe and unsubscribe parsed, the rest refused or invalid",
          "[live]") {
  const ClientRequest sub = parse_client_request(
      R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":1},{"id":7,"channelId":3}]})");
  REQUIRE(sub.kind == ClientRequest::Kind::kSubscribe);
  CHECK(sub.subscribe == std::vector<std::pair<std::uint32_t, std::uint32_t>>{{0, 1}, {7, 3}});
  const ClientRequest unsub = parse_client_request(R"({"op":"unsubscribe","subscriptionIds":[7]})");
  REQUIRE(unsub.kind == ClientRequest::Kind::kUnsubscribe);
  CHECK(unsub.unsubscribe == std::vector<std::uint32_t>{7});

  for (const char* refused :
       {R"({"op":"advertise","channels":[]})", R"({"op":"setParameters","parameters":[]})",
        R"({"op":"callService","serviceId":1})", R"({"op":"fetchAsset","uri":"file:///etc"})"}) {
    INFO(refused);
    const ClientRequest r = parse_client_request(refused);
    CHECK(r.kind == ClientRequest::Kind::kRefused);
    CHECK(r.problem.find("read-only") != std::string::npos);
  }
  std::string many = R"({"op":"subscribe","subscriptions":[)";
  for (int i = 0; i < 17; ++i)
    many += std::string(i ? "," : "") + R"({"id":)" + std::to_string(i) + R"(,"channelId":1})";
  many += "]}";
  for (const std::string& bad :
       {std::string("not json"), std::string("[1,2]"), std::string(R"({"op":7})"),
        std::string(R"({"op":"subscribe"})"), std::string(R"({"op":"bogus"})"),
        std::string(R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]})"),
        std::string(R"({"op":"subscribe","subscriptions":[{"id":4294967296,"channelId":1}]})"),
        std::string(R"({"op":"subscribe","subscriptions":[{"id":"0","channelId":1}]})"),
        std::string(R"({"op":"unsubscribe","subscriptionIds":[1.5]})"), many,
        std::string(1000, '[') + std::string(1000, ']'), std::string("\xff\xfe{", 3)}) {
    INFO(bad.substr(0, 80));
    const ClientRequest r = parse_client_request(bad);
    CHECK(r.kind == ClientRequest::Kind::kInvalid);
    CHECK_FALSE(r.problem.empty());
  }
}

TEST_CASE("[live] keys: ranges and addresses checked at their line", "[live][config][threads]") {
  CHECK(parse_config("", "t.toml").live.foxglove == false);
  CHECK(parse_config("", "t.toml").live.address == "127.0.0.1");
  const DaemonConfig c =
      parse_config("[live]\nfoxglove = true\nport = 9000\nmax_clients = 2\n", "t.toml");
  CHECK((c.live.foxglove && c.live.port == 9000 && c.live.max_clients == 2));
  const auto error = [](const std::string& text) {
    try {
      parse_config(text, "t.toml");
    } catch (const ConfigError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  CHECK(error("[live]\nport = 0\n").starts_with("t.toml:2:8: live.port: 0 is out of range"));
  CHECK(error("[live]\nmax_clients = 65\n").starts_with("t.toml:2:15: live.max_clients"));
  CHECK(error("[live]\naddress = \"localhost\"\n").starts_with("t.toml:2:11: live.address"));
  const auto r = test::run_command(test::pandarcapd_command() + " --foxglove-port 0 2>&1");
  CHECK(r.exit_code == 64);
  CHECK(r.out.find("live.port") != std::string::npos);
}

namespace {

// Whether a part of a health reason is what packets lost cost the stream and its frames: the
// decoder, behind the receiver, meets the hole in a later second than the drop was counted in
// (one TSan CI run's viewer saw only "5 azimuth gaps; 95600 points missing (lost packets)"; three
// TSan viewers beside a busy loop, "51 azimuth gaps; 698000 points missing (lost packets); 2
// stream changes (a restart, a gap, ...)").
bool loss_part(std::string_view part) {
  return part.ends_with(" azimuth gaps") || part.ends_with(" points missing (lost packets)") ||
         part.ends_with(
             " stream changes (a restart, a gap, a new speed, a clock step or a reversal)");
}

// Whether every part of a health reason is one a slowed build's load can cause: the kernel's
// buffer, the ring or the arenas overrun, what the packets so lost cost (loss_part), the packet
// rate behind for a second, or the simulated sensor's clock behind the host's by no more than
// `running_s`, the time it has run (starved, it sends its packets late: five TSan daemons on two
// busy cores said "sensor clock off by 1.4 s (behind the host)" within 1.5 s). A caller that
// takes losses checks, once the daemon has ended, that it counted the drops (losses_counted).
bool only_load_reasons(const std::string& reason, double running_s) {
  if (reason.empty()) return false;
  for (const std::string_view part : test::reason_parts(reason)) {
    const bool load = part.ends_with(" kernel drops") || part.ends_with(" ring overruns") ||
                      part.ends_with(" frames dropped (no free arena)") || loss_part(part) ||
                      part.starts_with("packet rate ") ||
                      test::clock_behind_by_at_most(part, running_s);
    if (!load) return false;
  }
  return true;
}

bool names_losses(const std::string& reason) {
  const auto parts = test::reason_parts(reason);
  return std::any_of(parts.begin(), parts.end(), loss_part);
}

// Whether every point a run's frames miss is a packet's the daemon counted as dropped (the
// kernel's or the ring's): a simulated sensor on loopback loses nothing else. `record`: the
// run's last health record; `lost`: a reason seen during the run named losses, so some packet
// must have been counted dropped. Each lost packet leaves its channel slots missing, 400 (10
// blocks x 40 channels, core/sensors/packet.hpp) on the simulated Pandar40P.
bool losses_counted(const json& record, bool lost) {
  constexpr std::uint64_t kSlotsPerPacket = kBlocks * kChannels;
  const std::uint64_t dropped =
      test::health_counter(record, "kernel_drops") + test::health_counter(record, "ring_overruns");
  INFO("points missing " << test::health_counter(record, "points_missing") << ", packets dropped "
                         << dropped);
  return test::health_counter(record, "points_missing") <= kSlotsPerPacket * dropped &&
         (!lost || dropped > 0);
}

}  // namespace

TEST_CASE("a TSan viewer's load allowance: a clock behind by no more than the run and never ahead",
          "[live]") {
  const std::string behind = "sensor clock off by 1.354 s (behind the host): not synchronised?";
  CHECK(only_load_reasons("3 kernel drops; " + behind, 2.0));
  CHECK(only_load_reasons("packet rate 2100/s (expected 3600 in dual return)", 2.0));
  CHECK_FALSE(only_load_reasons(behind, 1.0));  // behind by more than it ran
  CHECK_FALSE(only_load_reasons(
      "sensor clock off by 1.354 s (ahead of the host): not synchronised?", 60.0));
  CHECK_FALSE(
      only_load_reasons("sensor clock off by 3600 s (behind the host): not synchronised?", 60.0));
  CHECK_FALSE(
      only_load_reasons("sensor clock off by x s (behind the host): not synchronised?", 60.0));
  CHECK_FALSE(only_load_reasons("3 kernel drops; 2 packets rejected", 60.0));
  CHECK_FALSE(only_load_reasons("", 60.0));
  // What drops cost the frames, in a later second than the drops (losses_counted checks them).
  CHECK(only_load_reasons("5 azimuth gaps; 95600 points missing (lost packets)", 2.0));
  CHECK(only_load_reasons(
      "2 stream changes (a restart, a gap, a new speed, a clock step or a reversal)", 2.0));
  CHECK(names_losses("3 kernel drops; 5 azimuth gaps"));
  CHECK_FALSE(names_losses("3 kernel drops; packet rate 2100/s (expected 3600 in dual return)"));
  CHECK_FALSE(only_load_reasons("5 azimuth gaps; 2 sequence resets", 2.0));
  CHECK(losses_counted({{"counters", {{"points_missing", 800}, {"kernel_drops", 2}}}}, true));
  CHECK(losses_counted({{"counters", {{"points_missing", 800}, {"ring_overruns", 2}}}}, true));
  CHECK(losses_counted({{"counters", {{"points_missing", 0}}}}, false));
  CHECK_FALSE(
      losses_counted({{"counters", {{"points_missing", 801}, {"kernel_drops", 2}}}}, false));
  CHECK_FALSE(losses_counted({{"counters", {{"points_missing", 400}}}}, false));
  CHECK_FALSE(losses_counted({{"counters", {{"points_missing", 0}}}}, true));
}

TEST_CASE("Foxglove's client sees every channel live: PointCloud2 equal to the PCD frames, health",
          "[live][daemon][threads]") {
  if (!client_installed()) return;
  // Long enough for a node slow to start on a loaded machine; stopped once the client is done.
  LiveRun run("live-watch", 30);
  CHECK(run.daemon.log().find(run.url()) != std::string::npos);
  const auto r = run.watch(3);
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const json seen = json::parse(r.out);
  bool points = false, health = false;
  for (const json& c : seen["channels"]) {
    const std::string schema = c["schemaName"];
    if (schema.ends_with("PointCloud2") && c["encoding"] == "cdr") {
      points = c["topic"] == "/pandar/points" && c["schemaEncoding"] == "ros2msg";
    }
    if (c["encoding"] == "json" && c["topic"] == "/pandar/health") health = true;
  }
  CHECK(points);
  CHECK(health);
  CHECK(seen["server"]["capabilities"].empty());  // read-only: nothing offered
  CHECK(seen["clouds"] == 3);
  CHECK(seen["fields"] ==
        json::array({"x", "y", "z", "intensity", "ring", "return_type", "timestamp"}));
  CHECK(seen["frame_id"] == "pandar");
  CHECK(seen["width_times_step_is_data"] == true);
  // Each cloud is the PCD file of its revolution, byte for byte.
  CHECK(seen["matched"] == 3);
  CHECK(seen["health"].get<int>() >= 1);
  // The last health the viewer saw: ok. A TSan build's simulated sensor and pipeline, slowed
  // many times over on a busy machine, may fall behind the sensor's rate for a moment (one CI
  // run's viewer saw "degraded"): there, a reason made only of what that load can cause.
  const std::string state = seen["health_state"].is_string() ? seen["health_state"] : "";
  const std::string reason = seen["health_reason"].is_string() ? seen["health_reason"] : "";
  INFO("the last health seen: " << state << ": " << reason);
  if (test::kThreadSanitizerBuild && state == "degraded") {
    CHECK(only_load_reasons(reason, run.seconds_running()));
  } else {
    CHECK(state == "ok");
  }
  CHECK(seen["status"].get<int>() >= 1);
  CHECK(seen["statuses"].empty());
  run.daemon.signal(SIGTERM);
  REQUIRE(run.daemon.wait_exit(20s) == 0);
  const json h = test::last_health_record(run.dir / "out");
  REQUIRE(h.contains("live"));
  CHECK(h["live"]["messages_sent"].get<std::uint64_t>() >= 5);
  CHECK(h["live"]["clients"] == 0);
  CHECK(losses_counted(h, names_losses(reason)));
  const std::string prom = harness::read_file(run.dir / "out" / "health" / "pandarcap.prom");
  CHECK(prom.find("pandarcap_live_messages_sent_total{sensor=\"pandar40p\"}") != std::string::npos);
}

// arenas.points_per_frame below a revolution: the arenas are raised to what the model needs
// (arena_points), and every output must take what they hold. The live view's hand-over and its
// viewers' queues are sized from arenas.points_per_frame itself (live_points_capacity): with 1000,
// every frame is larger than its message may be, and each one is dropped for the viewer (counted
// in live.messages_dropped, the state still ok) while the PCDs and the MCAP get them all.
TEST_CASE("a small arenas.points_per_frame: the viewer still gets every frame, as the MCAP does",
          "[live][daemon][mcap][threads]") {
  if (!client_installed()) return;
  LiveRun run("live-small-arenas", 30,
              "[arenas]\npoints_per_frame = 1000\n[output]\nmcap = true\n");
  const auto r = run.watch(2);
  INFO(r.out);
  CHECK(r.exit_code == 0);  // 2: no cloud came within the client's 20 s
  run.daemon.signal(SIGTERM);
  REQUIRE(run.daemon.wait_exit(20s) == 0);
  const json h = test::last_health_record(run.dir / "out");
  INFO(h.dump());
  REQUIRE(h.contains("live"));
  // A single viewer that reads: nothing to drop. (A TSan build's writer, behind on a busy
  // machine, hands the frames on in bursts once it catches up, which a slow viewer's queue may
  // not hold: counted, as the other load tests allow under TSan.)
  if (!test::kThreadSanitizerBuild) CHECK(h["live"]["messages_dropped"] == 0);
  CHECK(test::health_counter(h, "mcap_messages_not_written") == 0);
  CHECK(test::health_counter(h, "write_errors") == 0);
}

TEST_CASE("a viewer that never reads costs the capture nothing: 10 s at 3600 packets/s",
          "[live][daemon][threads]") {
  if (!client_installed()) return;
  // 16 arenas (1.6 s of frames) rather than 4: a shared disk that holds one O_DIRECT write for
  // half a second under a parallel test's load is not the question here. A viewer that blocked
  // the writer would block it for the rest of the 10 s, and drop frames with any number.
  LiveRun run("live-stall", 10, "[arenas]\ncount = 16\n");
  harness::ChildProcess stalled(
      "/usr/bin/env", {"node", (client_dir() / "live_client.mjs").string(), "stall", run.url()},
      run.dir / "stalled.log");
  REQUIRE(
      harness::wait_until([&] { return stalled.log().find("stalled") != std::string::npos; }, 20s));
  // While it is stalled, another viewer still gets frames.
  const auto other = run.watch(2);
  INFO(other.out);
  CHECK(other.exit_code == 0);
  const auto status = run.daemon.wait_exit(30s);
  INFO(run.daemon.log());
  REQUIRE(status == 0);
  const std::string log = run.daemon.log();
  const std::size_t at = log.find("; frames ");
  REQUIRE(at != std::string::npos);
  const std::string frames = log.substr(at + 9, log.find(';', at + 1) - at - 9);
  INFO(frames);
  const json h = test::last_health_record(run.dir / "out");
  // A sanitizer build runs every thread several times slower: the stream's rate is not kept
  // there (the simulator falls behind, the ring overflows, counted), so only the release build
  // can show the capture lost nothing; the sanitizers look at the threads' hand-overs.
  if (!test::kSlowBuild) {
    CHECK(log.find("0 ring overruns, 0 kernel drops") != std::string::npos);
    CHECK(std::stoi(frames) >= 90);  // "N complete, ...": ten revolutions a second for 10 s
    CHECK(frames.find(" 0 dropped") != std::string::npos);
    CHECK(test::health_counter(h, "frames_dropped_no_arena") == 0);
    CHECK(test::health_counter(h, "datagrams_received") >= 35'000);
  }
  // The stalled viewer's frames were dropped for it, and counted.
  CHECK(h["live"]["messages_dropped"].get<std::uint64_t>() > 0);
  // Copying every frame for the viewers allocated nothing in the writer's loop (counted where
  // allocations can be: not under sanitizers).
  if (h["counters"].contains("hot_path_allocations_by_thread")) {
    CHECK(h["counters"]["hot_path_allocations_by_thread"]["writer"] == 0);
  }
}

TEST_CASE("the live view under abuse: churn, garbage, oversize frames, too many viewers",
          "[live][daemon][threads]") {
  LiveRun run("live-abuse", 30, "[live]\nmax_clients = 2\n");
  const std::uint16_t port = run.port;

  // 100 connections opened and closed in a row, each accepted.
  int accepted = 0;
  for (int i = 0; i < 100; ++i) {
    RawClient c(port);
    accepted += c.handshake().find(" 101 ") != std::string::npos;
  }
  CHECK(accepted == 100);

  // Without Foxglove's subprotocol: refused. Not a WebSocket request at all: refused.
  CHECK(RawClient(port).handshake("").find(" 400 ") != std::string::npos);
  CHECK(RawClient(port).raw_request("GET / HTTP/1.1\r\nHost: x\r\n\r\n").find("HTTP/1.1 4") == 0);

  {
    // Two viewers are the limit: a third is refused until one leaves.
    auto a = std::make_unique<RawClient>(port);
    RawClient b(port);
    CHECK(a->handshake().find(" 101 ") != std::string::npos);
    CHECK(b.handshake().find(" 101 ") != std::string::npos);
    CHECK(RawClient(port).handshake().find(" 503 ") != std::string::npos);
    a.reset();
    CHECK(harness::wait_until(
        [&] { return RawClient(port).handshake().find(" 101 ") != std::string::npos; }, 10s));

    // Garbage text, a binary message, an unknown channel: a status error each, still connected.
    CHECK(b.read_until("\"advertise\""));
    b.send_frame(0x81, "{{{ not json");
    CHECK(b.read_until("\"op\":\"status\""));
    b.send_frame(0x82, std::string("\x02\x01\x00\x00\x00", 5));
    CHECK(b.read_until("read-only"));
    b.send_frame(0x81, R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]})");
    CHECK(b.read_until("no channel 99"));
    b.send_frame(0x81, R"({"op":"advertise","channels":[{"id":1,"topic":"/x"}]})");
    CHECK(b.read_until("read-only"));
  }
  {
    // A client message over 64 KiB: closed with 1009 (message too big).
    RawClient c(port);
    REQUIRE(c.handshake().find(" 101 ") != std::string::npos);
    c.send_frame(0x81, std::string(100 * 1024, 'x'));
    int code = 0;
    CHECK(c.closed_by_server(code));
    CHECK((code == 1009 || code == 0));
  }
  {
    // An unmasked client frame breaks the protocol: closed.
    RawClient c(port);
    REQUIRE(c.handshake().find(" 101 ") != std::string::npos);
    c.send_frame(0x81, R"({"op":"unsubscribe","subscriptionIds":[]})", false);
    int code = 0;
    CHECK(c.closed_by_server(code));
  }
  {
    // A length field announcing 2^62 bytes: closed, nothing allocated for it.
    RawClient c(port);
    REQUIRE(c.handshake().find(" 101 ") != std::string::npos);
    std::string header = "\x81\xFF";
    header += std::string("\x40\x00\x00\x00\x00\x00\x00\x00", 8);
    header += "\x01\x02\x03\x04";
    c.raw_request(header);
    int code = 0;
    CHECK(c.closed_by_server(code));
  }
  // After all of it: a viewer is served, and the daemon stops cleanly, every viewer gone.
  CHECK(harness::wait_until(
      [&] { return RawClient(port).handshake().find(" 101 ") != std::string::npos; }, 10s));
  run.daemon.signal(SIGTERM);
  REQUIRE(run.daemon.wait_exit(30s) == 0);
  const std::string log = run.daemon.log();
  // The abuse cost the capture nothing (a TSan build may lose packets to its own load, counted).
  if (!test::kThreadSanitizerBuild) {
    CHECK(log.find("0 ring overruns, 0 kernel drops") != std::string::npos);
  }
  CHECK(log.find("refused: 2 viewers connected already (live.max_clients)") != std::string::npos);
}

TEST_CASE("the live view: another address is warned about", "[live][daemon][threads]") {
  {
    LiveRun run("live-address", 0.5, "[live]\naddress = \"127.0.0.2\"\n");
    REQUIRE(run.daemon.wait_exit(20s) == 0);
    CHECK(run.daemon.log().find("[warning] live view: listening on 127.0.0.2:" +
                                std::to_string(run.port) + ", not 127.0.0.1") != std::string::npos);
  }
}

// A TCP socket listening on 127.0.0.1:`port` (0: any free port), as another program holds it
// (foxglove_bridge listens on 8765, the live view's default).
static int listen_on(std::uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  REQUIRE(::listen(fd, 1) == 0);
  return fd;
}

static std::uint16_t bound_port(int fd) {
  sockaddr_in a{};
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  return ntohs(a.sin_port);
}

TEST_CASE("a live view port in use: the capture runs, degraded naming it, until it is free",
          "[live][daemon][threads]") {
  int fd = listen_on(0);
  const std::uint16_t port = bound_port(fd);
  const std::string taken = "live view: port " + std::to_string(port) + " in use";
  test::ScratchDir dir("live-port-in-use");
  const std::string out = (dir / "out").string();
  // The same port held on IPv6's loopback by another program (only there: IPV6_V6ONLY), where a
  // viewer that opens ws://localhost may land.
  const int fd6 = ::socket(AF_INET6, SOCK_STREAM | SOCK_CLOEXEC, 0);
  const int one = 1;
  ::setsockopt(fd6, IPPROTO_IPV6, IPV6_V6ONLY, &one, sizeof one);
  sockaddr_in6 a6{};
  a6.sin6_family = AF_INET6;
  a6.sin6_port = htons(port);
  a6.sin6_addr = in6addr_loopback;
  const bool ipv6 = ::bind(fd6, reinterpret_cast<sockaddr*>(&a6), sizeof a6) == 0 &&
                    ::listen(fd6, 1) == 0;  // false: no IPv6 on this host
  // --check-config tries the bind: a taken port is a warning, and the check passes (the
  // capture would run; the live view would bind later).
  const auto check =
      test::run_command(test::pandarcapd_command() + " --check-config --foxglove-port " +
                        std::to_string(port) + " --output-dir '" + out + "' 2>&1");
  INFO(check.out);
  CHECK(check.exit_code == 0);
  CHECK(check.out.find("warning: " + taken) != std::string::npos);
  CHECK(check.out.find("configuration OK") != std::string::npos);
  if (ipv6) {
    CHECK(check.out.find("warning: live view: port " + std::to_string(port) +
                         " is held on IPv6 (::1) by another program") != std::string::npos);
  }
  ::close(fd6);

  // Tried again every 0.5 s rather than 10 (a test hook), so that the test need not wait.
  const auto started = std::chrono::steady_clock::now();
  harness::ChildProcess daemon(
      "/usr/bin/env",
      {"PANDARCAP_TEST_LIVE_RETRY_MS=500", test::binary("pandarcapd").string(), "--allow-root",
       "--simulate", "--duration", "60", "--foxglove-port", std::to_string(port), "--output-dir",
       out},
      dir / "daemon.log");
  // Recording, degraded, the port named, the view not listening.
  json record;
  const auto last = [&] {
    const auto records = test::health_records(dir / "out");
    if (!records.empty()) record = records.back();
    return !records.empty();
  };
  REQUIRE(harness::wait_until(
      [&] {
        return last() && test::health_counter(record, "packets_accepted") > 0 &&
               record.value("reason", "").find(taken + " (retrying every 0.5 s)") !=
                   std::string::npos;
      },
      30s));
  INFO(daemon.log());
  CHECK(record["state"] == "degraded");
  CHECK(record["live"]["listening"] == false);
  CHECK(daemon.log().find("[warning] live view: cannot listen on 127.0.0.1:" +
                          std::to_string(port)) != std::string::npos);
  // Freed: bound at the next try, and the state is ok again (under TSan on a loaded machine:
  // degraded for load alone, only_load_reasons, the port no longer said).
  ::close(fd);
  REQUIRE(harness::wait_until(
      [&] {
        if (!last() || record["live"]["listening"] != true) return false;
        const std::string state = record.value("state", "");
        const double running_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
        return state == "ok" || (test::kThreadSanitizerBuild && state == "degraded" &&
                                 only_load_reasons(record.value("reason", ""), running_s));
      },
      30s));
  const std::string freed_reason = record.value("reason", "");  // the record the wait took
  CHECK(daemon.log().find("live view: port " + std::to_string(port) + " is free now") !=
        std::string::npos);
  if (client_installed()) {
    // Foxglove's client connects and is sent messages: health once a second at least, so 3 s
    // hold some even where a sanitizer's busy daemon is slow to publish (TSan's CI job once saw
    // none in 1 s, the client's start included).
    const auto view =
        test::run_command("node '" + (client_dir() / "live_client.mjs").string() +
                          "' view ws://127.0.0.1:" + std::to_string(port) + " 3 2>&1");
    INFO(view.out);
    CHECK(view.exit_code == 0);
    const json seen = json::parse(view.out, nullptr, false);
    REQUIRE_FALSE(seen.is_discarded());
    CHECK(seen["messages"].get<int>() > 0);
  }
  daemon.signal(SIGTERM);
  CHECK(daemon.wait_exit(20s) == 0);
  CHECK(losses_counted(test::last_health_record(dir / "out"), names_losses(freed_reason)));
}
