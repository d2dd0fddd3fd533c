// The PTC client (daemon/ptc/) against the simulated sensor's server and against a hostile one
// (tests/support/hostile_ptc_server.hpp): every command answered, and every misbehaviour of
// spec §6 a bounded, named failure, counted, with the connection dropped.
#include <catch2/catch.hpp>
#include <chrono>

#include "core/sim/simulated_unit.hpp"
#include "daemon/ptc/ptc_client.hpp"
#include "daemon/ptc/sensor_queries.hpp"
#include "daemon/ptc/simulated_ptc_server.hpp"
#include "support/hostile_ptc_server.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using test::Hostile;
using test::HostilePtcServer;

namespace {

PtcClientOptions local(std::uint16_t port, std::chrono::milliseconds timeout = 1000ms) {
  return PtcClientOptions{.address = "127.0.0.1", .port = port, .timeout = timeout};
}

// The time a failure took, to check it is bounded by the deadline (with room for a busy
// machine: the bound is what matters, never how fast).
struct Stopwatch {
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
};

}  // namespace

TEST_CASE("PTC client reads every command from the simulated sensor on one connection",
          "[ptc][threads]") {
  const SimulatedUnit unit = simulated_unit(600, 0x39, true, 2368);
  SimulatedPtcServer server(unit);
  PtcClient client(local(server.port()));

  const Fetched<Calibration> calibration = fetch_calibration(client);
  REQUIRE(calibration.value);
  CHECK(calibration.value->elevation_deg == unit.calibration.elevation_deg);
  CHECK(calibration.value->azimuth_offset_deg == unit.calibration.azimuth_offset_deg);
  CHECK(calibration.value->source == "sensor " + client.endpoint());

  const auto inventory = fetch_inventory(client);
  REQUIRE(inventory.value);
  CHECK(inventory.value->serial == "PCSIM40P00000001");
  CHECK(inventory.value->lines == 40);

  const auto settings = fetch_settings(client);
  REQUIRE(settings.value);
  CHECK(settings.value->clock_source == ptc::kClockSourcePtp);
  CHECK(settings.value->udp_sequence == 1);

  const auto status = fetch_status(client);
  REQUIRE(status.value);
  CHECK(status.value->motor_rpm == 600);
  CHECK(status.value->ptp_state == static_cast<std::uint8_t>(ptc::PtpState::kLocked));
  server.set_ptp_state(static_cast<std::uint8_t>(ptc::PtpState::kTracking));
  const auto tracking = fetch_status(client);
  REQUIRE(tracking.value);
  CHECK(ptc::ptp_state_name(tracking.value->ptp_state) == "tracking");

  CHECK(client.requests() == 5);
  CHECK(client.errors() == 0);
  CHECK(server.requests() == 5);

  // 0x06 is not supported by the simulated unit (nor, as far as known, by every 40P firmware).
  // Asked for the feature, "unsupported" is an answer, not a failure: not counted.
  const auto no_ptp = fetch_ptp_status(client);
  REQUIRE(no_ptp.error);
  CHECK(no_ptp.error->return_code == 0x05);
  CHECK_THAT(no_ptp.error->message, Catch::Contains("not supported by this sensor"));
  CHECK(client.errors() == 0);
  // Asked as a plain request, the same answer is an error return code, counted, and the next
  // request reconnects and succeeds.
  const PtcReply ptp = client.request(ptc::Command::kPtpDiagnostics, std::vector<std::uint8_t>{1});
  REQUIRE(ptp.error);
  CHECK(ptp.error->kind == ptc::ErrorKind::kErrorCode);
  CHECK(ptp.error->return_code == 0x05);
  CHECK_THAT(ptp.error->message, Catch::Contains("unsupported command"));
  CHECK(client.errors(ptc::ErrorKind::kErrorCode) == 1);
  CHECK(fetch_status(client).value);
}

TEST_CASE("PTC client: a refused connection is a connect failure at once", "[ptc]") {
  test::RefusingPort refusing;
  PtcClient client(local(refusing.port));
  const Stopwatch watch;
  const auto status = fetch_status(client);
  REQUIRE(status.error);
  CHECK(status.error->kind == ptc::ErrorKind::kConnectFailed);
  CHECK_THAT(status.error->message, Catch::Contains("127.0.0.1:" + std::to_string(refusing.port)) &&
                                        Catch::Contains("status") && Catch::Contains("refused"));
  CHECK(watch.seconds() < 5);
  CHECK(client.errors(ptc::ErrorKind::kConnectFailed) == 1);
}

TEST_CASE("PTC client: a server that accepts and never answers times out at the deadline",
          "[ptc][threads]") {
  HostilePtcServer server(Hostile::kSilent);
  PtcClient client(local(server.port(), 500ms));
  const Stopwatch watch;
  const auto calibration = fetch_calibration(client);
  REQUIRE(calibration.error);
  CHECK(calibration.error->kind == ptc::ErrorKind::kTimeout);
  CHECK_THAT(calibration.error->message, Catch::Contains("timed out after 500 ms"));
  CHECK(watch.seconds() >= 0.45);
  CHECK(watch.seconds() < 5);
}

TEST_CASE("PTC client: a server trickling a byte at a time is given up at the deadline",
          "[ptc][threads]") {
  // 62 bytes at one per 200 ms would take 12 s: the deadline is the whole answer's, 1 s.
  HostilePtcServer server(Hostile::kTrickle, 200);
  PtcClient client(local(server.port(), 1000ms));
  const Stopwatch watch;
  const auto status = fetch_status(client);
  REQUIRE(status.error);
  CHECK(status.error->kind == ptc::ErrorKind::kTimeout);
  CHECK(watch.seconds() < 6);
}

TEST_CASE("PTC client: a patient client reads a trickled answer whole", "[ptc][threads]") {
  HostilePtcServer server(Hostile::kTrickle, 1);
  PtcClient client(local(server.port(), 20'000ms));
  const auto status = fetch_status(client);
  REQUIRE(status.value);
  CHECK(status.value->uptime_s == 100);
}

TEST_CASE("PTC client: every malformed answer is a named, counted failure", "[ptc][threads]") {
  struct Case {
    Hostile behaviour;
    ptc::ErrorKind kind;
    const char* words;
  };
  const Case cases[] = {
      // Closed with the request unread: a reset or an end of stream, by timing; both incomplete.
      {Hostile::kCloseAtOnce, ptc::ErrorKind::kIncomplete, "reading the response header"},
      {Hostile::kCutHeader, ptc::ErrorKind::kIncomplete, "(5 of 8 bytes)"},
      {Hostile::kWrongMagic, ptc::ErrorKind::kBadMagic, "not a PTC server"},
      {Hostile::kWrongCommand, ptc::ErrorKind::kUnrelatedResponse, "0x07"},
      {Hostile::kErrorCode, ptc::ErrorKind::kErrorCode, "0x03 (invalid data)"},
      {Hostile::kErrorCodePayload, ptc::ErrorKind::kErrorCode, "0x07 (other error)"},
      {Hostile::kEmptyPayload, ptc::ErrorKind::kUnexpectedPayload, "0 bytes, expected 54"},
      {Hostile::kHugeLength, ptc::ErrorKind::kOversize, "4294967295"},
      {Hostile::kCutPayload, ptc::ErrorKind::kIncomplete, "(10 of 100 bytes)"},
      {Hostile::kShortStatus, ptc::ErrorKind::kUnexpectedPayload, "40 bytes, expected 54"},
  };
  for (const Case& c : cases) {
    INFO("expecting " << ptc::to_string(c.kind) << ": " << c.words);
    HostilePtcServer server(c.behaviour);
    PtcClient client(local(server.port(), 2000ms));
    const Stopwatch watch;
    const auto status = fetch_status(client);
    REQUIRE(status.error);
    CHECK(status.error->kind == c.kind);
    CHECK_THAT(status.error->message, Catch::Contains(c.words));
    CHECK(client.errors() == 1);
    CHECK(client.errors(c.kind) == 1);
    // None of these waits for the deadline: each is seen as soon as its bytes arrive.
    CHECK(watch.seconds() < 1.9);
    // The connection was dropped: the next request opens a new one.
    fetch_status(client);
    CHECK(server.connections() == 2);
  }
}

TEST_CASE("PTC client: a longer status (newer firmware) parses with the extra bytes counted",
          "[ptc][threads]") {
  HostilePtcServer server(Hostile::kLongStatus);
  PtcClient client(local(server.port()));
  const auto status = fetch_status(client);
  REQUIRE(status.value);
  CHECK(status.extra_bytes == 6);
  CHECK(status.value->motor_rpm == 600);
}

TEST_CASE("PTC client: a calibration answer that is not a 40-channel table is refused",
          "[ptc][calibration][threads]") {
  HostilePtcServer server(Hostile::kBadCalibration);
  PtcClient client(local(server.port()));
  const auto calibration = fetch_calibration(client);
  REQUIRE(calibration.error);
  CHECK(calibration.error->kind == ptc::ErrorKind::kUnexpectedPayload);
  CHECK_THAT(calibration.error->message, Catch::Contains("not a Pandar40P calibration table") &&
                                             Catch::Contains("channels missing: 40"));
}

TEST_CASE("PTC client: an address that is not IPv4 is refused before any connection", "[ptc]") {
  CHECK_THROWS_AS(PtcClient(PtcClientOptions{.address = "sensor.local"}), std::invalid_argument);
}

TEST_CASE("PTC client reads the PTP offset from a sensor that answers 0x06", "[ptc][threads]") {
  SimulatedUnit unit = simulated_unit();
  unit.answers_ptp_diagnostics = true;
  unit.ptp_offset_ns = -1234;
  SimulatedPtcServer server(unit);
  PtcClient client(local(server.port()));
  const auto ptp = fetch_ptp_status(client);
  REQUIRE(ptp.value);
  CHECK(ptp.value->master_offset_ns == -1234);
  CHECK(ptp.value->state == 2);
  CHECK(client.errors() == 0);
}
