// recording_sidecars: the names of the files beside a recording (its calibration and sensor
// facts), for every name a recording has in its life (.part, finished, compressed, a collision's).
#include <catch2/catch.hpp>
#include <string>

#include "daemon/pcap/recording_sidecars.hpp"

using pandarcap::recording_sidecars;
using pandarcap::recording_stem;

TEST_CASE("a recording's sidecars share its stem, whatever its extension", "[recording_sidecars]") {
  const auto [path, stem] = GENERATE(table<std::string, std::string>({
      {"raw/pandarcap_20261122T120000Z_0001.pcap", "pandarcap_20261122T120000Z_0001"},
      {"raw/pandarcap_20261122T120000Z_0001.pcap.zst", "pandarcap_20261122T120000Z_0001"},
      {"raw/pandarcap_20261122T120000Z_0001.pcap.part", "pandarcap_20261122T120000Z_0001"},
      {"raw/pandarcap_20261122T120000Z_0001.pcap.zst.part", "pandarcap_20261122T120000Z_0001"},
      {"/d/raw/pandarcap_20261122T120000Z_0001_dup1.pcap", "pandarcap_20261122T120000Z_0001_dup1"},
      {"x.pcap", "x"},
      {"/a.pcap/b.pcap.zst", "b"},
  }));
  CAPTURE(path);
  REQUIRE(recording_stem(path) == stem);
  const auto sidecars = recording_sidecars(path);
  REQUIRE(sidecars);
  const std::string directory = path.substr(0, path.rfind('/') + 1);  // npos + 1 == 0
  CHECK(sidecars->calibration_csv == directory + stem + ".calibration.csv");
  CHECK(sidecars->sensor_json == directory + stem + ".sensor.json");
}

TEST_CASE("names that are not a recording of ours have no sidecars", "[recording_sidecars]") {
  const std::string path =
      GENERATE(as<std::string>{}, "raw/x.mcap", "raw/x.pcapng", "raw/.pcap", ".pcap.zst",
               "raw/x.pcap.zst.tmp", "raw/x.zst", "raw/", "", "raw/x.pcap/", "raw/calibration.csv");
  CAPTURE(path);
  CHECK_FALSE(recording_stem(path));
  CHECK_FALSE(recording_sidecars(path));
}
