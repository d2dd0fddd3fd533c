// The TOML configuration: defaults, the documented example, round trips through --print-config,
// and an error with a file:line:col location for every kind of bad input.
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <string>

#include "config/config_loader.hpp"
#include "config/suggest.hpp"

using namespace pandarcap;

namespace {

// The ConfigError message for `text`, or "(accepted)".
std::string error_of(const std::string& text) {
  try {
    parse_config(text, "t.toml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "(accepted)";
}

// A configuration with every key away from its default.
DaemonConfig everything_changed() {
  DaemonConfig c;
  c.log_level = "debug";
  c.sensor.sensor_ip = "192.168.1.201";
  c.sensor.host_ip = "192.168.1.100";
  c.sensor.multicast_ip = "239.1.2.3";
  c.sensor.multicast_interface_ip = "192.168.1.100";
  c.sensor.data_port = 2369;
  c.sensor.udp_socket_receive_buffer_size_bytes = 16u << 20;
  c.sensor.return_mode = "dual";
  c.sensor.rotation_speed = 1200;
  c.sensor.cut_angle = 359.99;
  c.sensor.min_range = 0.05;
  c.sensor.max_range = 1e-1 + 130.2;  // not exactly representable: checks shortest round trip
  c.sensor.dual_return_distance_threshold = 0.0;
  c.sensor.calibration_file = "/etc/pandar \"40p\"\\cal\tv2.csv";
  c.sensor.firing_time_correction = true;
  c.ring.slots = 1 << 20;
  c.ring.receive_batch = 1024;
  c.arenas.count = 64;
  c.arenas.points_per_frame = 10'000'000;
  c.arenas.packets_per_frame = 65536;
  c.output.directory = "/var/lib/pandarcap";
  c.output.frames = false;
  c.output.frame_decimation = 10;
  c.output.frames_max_files = 1000;
  c.output.frames_max_bytes = 5'000'000'000;
  c.output.pcap = false;
  c.output.pcap_rotate_bytes = 0;
  c.output.pcap_rotate_seconds = 3600;
  c.output.pcap_max_files = 24;
  c.output.pcap_max_bytes = 1ull << 40;
  c.health.sensor_name = "front-left";
  c.health.no_data_timeout_seconds = 0.5;
  c.health.prometheus = false;
  c.health.jsonl = false;
  c.health.jsonl_rotate_bytes = 0;
  c.health.directory = "/var/log/pandarcap/front";
  c.health.prometheus_file = "/var/lib/prometheus/node-exporter/pandarcap-front.prom";
  c.threads.receive_cpu = 1;
  c.threads.decode_cpu = 0;
  c.threads.writer_cpu = 1023;
  c.threads.receive_priority = 50;
  c.threads.decode_priority = 40;
  c.threads.writer_priority = 1;
  c.threads.lock_memory = true;
  return c;
}

}  // namespace

TEST_CASE("An empty document is the defaults", "[config]") {
  CHECK(to_toml(parse_config("", "empty.toml")) == to_toml(DaemonConfig{}));
}

TEST_CASE("The documented example config/pandarcap.toml parses to the defaults", "[config]") {
  const auto path = std::filesystem::path(PANDARCAP_SOURCE_DIR) / "config" / "pandarcap.toml";
  CHECK(to_toml(load_config_file(path)) == to_toml(DaemonConfig{}));
}

TEST_CASE("to_toml reads back to the same configuration", "[config]") {
  const DaemonConfig changed = everything_changed();
  const std::string text = to_toml(changed);
  CHECK(text != to_toml(DaemonConfig{}));
  const DaemonConfig back = parse_config(text, "printed.toml");
  CHECK(to_toml(back) == text);
  // Spot checks that the values themselves survived, not only their printing.
  CHECK(back.sensor.calibration_file == changed.sensor.calibration_file);
  CHECK(back.sensor.max_range == changed.sensor.max_range);
  CHECK(back.output.pcap_max_bytes == changed.output.pcap_max_bytes);
  CHECK(back.ring.slots == changed.ring.slots);
  CHECK_FALSE(back.health.jsonl);
  CHECK(back.threads.receive_priority == 50);
  CHECK(back.threads.lock_memory);
}

TEST_CASE("A float key accepts an integer - an integer key refuses a float", "[config]") {
  CHECK(parse_config("[sensor]\nmax_range = 120\n", "t.toml").sensor.max_range == 120.0);
  CHECK(error_of("[sensor]\ndata_port = 2368.0\n") ==
        "t.toml:2:13: sensor.data_port: expected an integer, found a floating-point number");
}

TEST_CASE("Syntax errors name the line and column", "[config]") {
  CHECK(error_of("log_level = \"info\"\n[sensor\n").rfind("t.toml:2:8: ", 0) == 0);
  CHECK(error_of("[sensor]\ndata_port = \n").rfind("t.toml:2:", 0) == 0);
  CHECK(error_of("[sensor]\n[sensor]\n").rfind("t.toml:2:", 0) == 0);
}

TEST_CASE("Unknown keys and tables are errors, with the name that was probably meant", "[config]") {
  CHECK(error_of("[sensor]\ndata_prot = 2368\n") ==
        "t.toml:2:1: sensor.data_prot: unknown key (did you mean data_port?)");
  CHECK(error_of("verbose = true\n") == "t.toml:1:1: verbose: unknown key or table");
  CHECK(error_of("[snesor]\n") ==
        "t.toml:1:2: snesor: unknown key or table (did you mean sensor?)");
  // A key in the wrong table: where it belongs.
  CHECK(error_of("[output]\nsensor_ip = \"192.168.1.201\"\n") ==
        "t.toml:2:1: output.sensor_ip: unknown key (sensor_ip is a key of [sensor])");
  CHECK(
      error_of("[sensor]\nlog_level = \"info\"\n") ==
      "t.toml:2:1: sensor.log_level: unknown key (log_level is a top-level key, before any table)");
  // Nothing near enough: no guess.
  CHECK(error_of("[ring]\nspeed = 3\n") == "t.toml:2:1: ring.speed: unknown key");
  CHECK(error_of("[sensor.extra]\nx = 1\n").rfind("t.toml:1:", 0) == 0);
  CHECK(error_of("sensor = 3\n") == "t.toml:1:10: sensor: expected a table, found an integer");
}

TEST_CASE("Every problem in a file is reported at once, in the file's order", "[config]") {
  // "zz" sorts after "sensor" in the document but comes first in the file; the unknown key,
  // the wrong type, the value out of range and the check between keys all come out, one a line.
  CHECK(error_of("zz = 1\n"
                 "[sensor]\n"
                 "bad = 2\n"
                 "data_port = 70000\n"
                 "min_range = 5.0\n"
                 "max_range = 4.0\n"
                 "[output]\n"
                 "frames = \"yes\"\n"
                 "pcd_fields = \"xyzi\"\n") ==
        "t.toml:1:1: zz: unknown key or table\n"
        "t.toml:3:1: sensor.bad: unknown key\n"
        "t.toml:4:13: sensor.data_port: 70000 is out of range (1..65535)\n"
        "t.toml:6:13: sensor.max_range: 4 must be greater than sensor.min_range (5)\n"
        "t.toml:8:10: output.frames: expected true or false, found a string\n"
        "t.toml:9:14: output.pcd_fields: \"xyzi\" is not one of pcl, pandarcap, velodyne, "
        "autoware");
}

TEST_CASE("Did you mean: near names only, transpositions count one", "[config]") {
  const std::vector<std::string_view> names{"data_port", "host_ip", "sensor_ip", "max_range"};
  CHECK(edit_distance("data_prot", "data_port") == 1);
  CHECK(edit_distance("", "abc") == 3);
  CHECK(edit_distance("kitten", "sitting") == 3);
  CHECK(nearest("data_prot", names) == "data_port");
  CHECK(nearest("sensorip", names) == "sensor_ip");
  CHECK(nearest("maxrange", names) == "max_range");
  CHECK(nearest("port", names) == std::nullopt);  // 5 edits from data_port: another word
  CHECK(nearest("zz", names) == std::nullopt);
}

TEST_CASE("Wrong types are errors naming what was expected", "[config]") {
  CHECK(error_of("[output]\nframes = \"yes\"\n") ==
        "t.toml:2:10: output.frames: expected true or false, found a string");
  CHECK(error_of("[sensor]\nmax_range = \"far\"\n") ==
        "t.toml:2:13: sensor.max_range: expected a number, found a string");
  CHECK(error_of("log_level = 3\n") ==
        "t.toml:1:13: log_level: expected a string, found an integer");
  CHECK(error_of("[ring]\nslots = [4096]\n") ==
        "t.toml:2:9: ring.slots: expected an integer, found an array");
}

TEST_CASE("Integers are range-checked before narrowing, so nothing wraps", "[config]") {
  CHECK(error_of("[sensor]\ndata_port = 70000\n") ==
        "t.toml:2:13: sensor.data_port: 70000 is out of range (1..65535)");
  CHECK(error_of("[sensor]\ndata_port = 65537\n") ==
        "t.toml:2:13: sensor.data_port: 65537 is out of range (1..65535)");
  CHECK(error_of("[sensor]\ndata_port = 0\n") ==
        "t.toml:2:13: sensor.data_port: 0 is out of range (1..65535)");
  CHECK(error_of("[output]\nframes_max_files = -1\n") ==
        "t.toml:2:20: output.frames_max_files: -1 is out of range (0..9223372036854775807)");
  CHECK(error_of("[ring]\nreceive_batch = 4294967297\n") ==
        "t.toml:2:17: ring.receive_batch: 4294967297 is out of range (1..1024)");
  CHECK(error_of("[arenas]\ncount = 1\n") == "t.toml:2:9: arenas.count: 1 is out of range (2..64)");
  CHECK(error_of("[threads]\nreceive_cpu = -2\n") ==
        "t.toml:2:15: threads.receive_cpu: -2 is out of range (-1..1023)");
  CHECK(error_of("[threads]\ndecode_priority = 100\n") ==
        "t.toml:2:19: threads.decode_priority: 100 is out of range (0..99)");
  CHECK(error_of("[output]\nframe_decimation = 0\n").find("output.frame_decimation: 0 is out") !=
        std::string::npos);
}

TEST_CASE("Reals must be finite and in range", "[config]") {
  CHECK(error_of("[sensor]\ncut_angle = 360.0\n") ==
        "t.toml:2:13: sensor.cut_angle: 360 is out of range ([0, 360))");
  CHECK(error_of("[sensor]\nmin_range = -0.5\n") ==
        "t.toml:2:13: sensor.min_range: -0.5 is out of range (>= 0)");
  CHECK(error_of("[sensor]\nmax_range = inf\n") ==
        "t.toml:2:13: sensor.max_range: inf is out of range (> 0, finite)");
  CHECK(error_of("[sensor]\ndual_return_distance_threshold = nan\n").find("finite") !=
        std::string::npos);
  CHECK(error_of("[health]\nno_data_timeout_seconds = 0\n") ==
        "t.toml:2:27: health.no_data_timeout_seconds: 0 is out of range ((0, 86400])");
}

TEST_CASE("Checks between keys point at the key that must change", "[config]") {
  CHECK(error_of("[sensor]\nmin_range = 5.0\nmax_range = 5.0\n") ==
        "t.toml:3:13: sensor.max_range: 5 must be greater than sensor.min_range (5)");
  CHECK(error_of("[ring]\nslots = 3000\n") == "t.toml:2:9: ring.slots: 3000 is not a power of two");
  CHECK(error_of("[ring]\nslots = 64\nreceive_batch = 128\n") ==
        "t.toml:3:17: ring.receive_batch: 128 is more than ring.slots (64)");
  CHECK(error_of("[sensor]\nrotation_speed = 900\n") ==
        "t.toml:2:18: sensor.rotation_speed: 900 RPM is not a Pandar40P motor speed (600 or 1200)");
  // With max_range absent its default is compared, and the message has no line to point at.
  CHECK(error_of("[sensor]\nmin_range = 250.0\n") ==
        "t.toml: sensor.max_range: 200 must be greater than sensor.min_range (250)");
}

TEST_CASE("Strings are checked: addresses, names from a fixed set, labels", "[config]") {
  CHECK(error_of("[sensor]\nhost_ip = \"192.168.1.300\"\n") ==
        "t.toml:2:11: sensor.host_ip: \"192.168.1.300\" is not an IPv4 address (a.b.c.d)");
  CHECK(error_of("[sensor]\nhost_ip = \"\"\n").find("is not an IPv4 address") != std::string::npos);
  CHECK(error_of("[sensor]\nsensor_ip = \"lidar.local\"\n").find("sensor.sensor_ip") !=
        std::string::npos);
  CHECK(error_of("[sensor]\nmulticast_ip = \"192.168.1.1\"\n") ==
        "t.toml:2:16: sensor.multicast_ip: \"192.168.1.1\" is not a multicast address "
        "(224.0.0.0/4)");
  CHECK(error_of("[sensor]\nreturn_mode = \"first\"\n") ==
        "t.toml:2:15: sensor.return_mode: \"first\" is not one of any, last, strongest, dual");
  CHECK(error_of("log_level = \"verbose\"\n")
            .find("trace, debug, info, warn, error, critical, off") != std::string::npos);
  CHECK(error_of("[health]\nsensor_name = \"a\\\"b\"\n").find("health.sensor_name: must not") !=
        std::string::npos);
  CHECK(error_of("decoder = \"fastest\"\n") ==
        "t.toml:1:11: decoder: must be auto, scalar, sse4, avx2, avx512, neon, sve or sve2");
  CHECK(error_of("decoder = \"avx512\"\n") == "(accepted)");  // the CPU is checked at start-up
  CHECK(error_of("[output]\ndirectory = \"\"\n") ==
        "t.toml:2:13: output.directory: must not be empty");
  CHECK(error_of("[health]\nprometheus_file = \"/var/lib/x/pandarcap.txt\"\n") ==
        "t.toml:2:19: health.prometheus_file: \"/var/lib/x/pandarcap.txt\" must be a file name "
        "ending in .prom (node_exporter's textfile collector reads no other)");
  CHECK(error_of("[health]\nprometheus_file = \"/var/lib/x/.prom\"\n").find("must be a file") !=
        std::string::npos);
  CHECK(error_of("[health]\nprometheus_file = \"a.prom\"\n") == "(accepted)");
  CHECK(error_of("[sensor]\nsensor_ip = \"\"\nmulticast_ip = \"239.255.0.1\"\n") == "(accepted)");
}

TEST_CASE("validate_config checks values set on the command line by name", "[config]") {
  DaemonConfig c;
  CHECK_NOTHROW(validate_config(c, "command line"));
  c.sensor.max_range = 0.3;  // equal to min_range
  CHECK_THROWS_WITH(validate_config(c, "command line"),
                    "command line: sensor.max_range: 0.3 must be greater than sensor.min_range "
                    "(0.3)");
  c = DaemonConfig{};
  c.ring.receive_batch = 0;
  CHECK_THROWS_WITH(validate_config(c, "site.toml"),
                    "site.toml: ring.receive_batch: 0 is out of range (1..1024)");
}

TEST_CASE("Files: an unreadable file is named, a readable one is parsed with its name",
          "[config]") {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("pandarcap-config-test-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto missing = dir / "missing.toml";
  CHECK_THROWS_WITH(load_config_file(missing),
                    missing.string() + ": cannot read: No such file or directory");
  const auto bad = dir / "bad.toml";
  std::ofstream(bad) << "# comment\n[arenas]\ncount = 100\n";
  CHECK_THROWS_WITH(load_config_file(bad),
                    bad.string() + ":3:9: arenas.count: 100 is out of range (2..64)");
  // A huge file is refused after a bounded read, not loaded into memory.
  const auto huge = dir / "huge.toml";
  std::ofstream(huge).close();
  std::filesystem::resize_file(huge, 4u << 20);
  CHECK_THROWS_WITH(
      load_config_file(huge),
      huge.string() + ":1:1: larger than 1048576 bytes: not a pandarcapd configuration");
  // An endless device and a FIFO with no writer are refused at once, nothing read (a FIFO's open
  // would wait for a writer, with the daemon's signals blocked).
  const std::string not_regular =
      ": not a regular file (a FIFO, socket, device or directory): not a pandarcapd configuration";
  CHECK_THROWS_WITH(load_config_file("/dev/zero"), "/dev/zero" + not_regular);
  const auto fifo = dir / "fifo.toml";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK_THROWS_WITH(load_config_file(fifo), fifo.string() + not_regular);
  std::filesystem::remove_all(dir);
}

TEST_CASE("Nesting past 32 levels is refused before parsing, where the limit is crossed",
          "[config]") {
  const auto repeat = [](const std::string& s, int n) {
    std::string out;
    for (int i = 0; i < n; ++i)
      out += s;
    return out;
  };
  // ~40 000 levels once overflowed the parser's stack (SIGSEGV): each form is refused with its
  // place, however deep it goes.
  const std::string dotted_key = "a" + repeat(".a", 40000) + " = 1\n";
  const std::string header = "[" + repeat("a.", 40000) + "a]\n";
  const std::string arrays = "x = " + repeat("[", 40000) + repeat("]", 40000) + "\n";
  const std::string inline_tables = "x = " + repeat("{a = ", 40000) + "1" + repeat("}", 40000);
  for (const std::string& text : {dotted_key, header, arrays, inline_tables}) {
    const std::string error = error_of(text);
    INFO(error);
    CHECK(error.rfind("t.toml:1:", 0) == 0);
    CHECK(error.find("nested more than 32 levels deep") != std::string::npos);
  }
  CHECK(error_of("[sensor]\nx = " + repeat("[", 33) + repeat("]", 33) + "\n")
            .rfind("t.toml:2:37: nested more than 32 levels deep", 0) == 0);
  // Dots that are not keys do not count: in strings, comments, numbers; and 32 levels pass the
  // guard (toml++ then reports what it finds: an unknown key).
  const std::string many_dots = repeat(".", 100);
  CHECK(
      parse_config("# " + many_dots + "\n[output]\ndirectory = \"a" + many_dots + "\"\n", "t.toml")
          .output.directory == "a" + many_dots);
  CHECK(parse_config("[output]\ndirectory = '''x" + repeat("\n.", 50) + "'''\n", "t.toml")
            .output.directory == "x" + repeat("\n.", 50));
  CHECK(error_of("[sensor]\nx = [" + repeat("1.5, ", 100) + "1.5]\n") ==
        "t.toml:2:1: sensor.x: unknown key");
  CHECK(error_of("a" + repeat(".a", 31) + " = 1\n").find("nested") == std::string::npos);
}

TEST_CASE("The latency budget is 0..1000 ms", "[config]") {
  CHECK(parse_config("[latency]\nbudget_ms = 0\n", "t.toml").latency.budget_ms == 0);
  CHECK(DaemonConfig{}.latency.budget_ms == 5);
  CHECK(error_of("[latency]\nbudget_ms = 1001\n") ==
        "t.toml:2:13: latency.budget_ms: 1001 is out of range (0..1000)");
}
