// Calibration CSV loader: good files in every accepted dialect, and each kind of bad file with
// the file:line:col it must point at.
#include <sys/stat.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/decode/calibration.hpp"
#include "daemon/io/calibration_file.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

// A valid table whose values encode the channel: elevation = id/10, azimuth = -id/100.
std::string table(const std::string& header, const std::string& eol, bool trailing_newline) {
  std::string text = header.empty() ? "" : header + eol;
  for (int id = 1; id <= kChannels; ++id) {
    text +=
        std::to_string(id) + "," + std::to_string(id / 10.0) + "," + std::to_string(-id / 100.0);
    if (id < kChannels || trailing_newline) text += eol;
  }
  return text;
}

void require_error(const std::string& text, const std::string& location, const std::string& words) {
  try {
    (void)Calibration::parse(text, "cal.csv");
    FAIL("no error for a bad file; expected " << location);
  } catch (const CalibrationError& e) {
    const std::string message = e.what();
    INFO(message);
    CHECK(message.rfind("cal.csv:" + location + ": ", 0) == 0);
    CHECK(message.find(words) != std::string::npos);
  }
}

// Replaces line `line` (1-based) of `text`.
std::string with_line(std::string text, int line, const std::string& replacement) {
  std::size_t begin = 0;
  for (int i = 1; i < line; ++i)
    begin = text.find('\n', begin) + 1;
  const std::size_t end = text.find('\n', begin);
  return text.replace(begin, end - begin, replacement);
}

}  // namespace

TEST_CASE("calibration parses LF, CRLF, with and without trailing newline", "[calibration]") {
  for (const std::string& eol : {std::string("\n"), std::string("\r\n")}) {
    for (bool trailing : {true, false}) {
      for (const std::string& header : {std::string("Laser id,Elevation,Azimuth"),
                                        std::string("Channel,Elevation,Azimuth"), std::string()}) {
        const Calibration c = Calibration::parse(table(header, eol, trailing), "t.csv");
        for (int ch = 0; ch < kChannels; ++ch) {
          CHECK(c.elevation_deg[ch] == Approx((ch + 1) / 10.0));
          CHECK(c.azimuth_offset_deg[ch] == Approx(-(ch + 1) / 100.0));
        }
        CHECK(c.source == "t.csv");
        CHECK_FALSE(c.is_nominal());
      }
    }
  }
}

TEST_CASE("rows may come in any order, with spaces and blank lines", "[calibration]") {
  std::string text = "Laser id, Elevation, Azimuth\n\n";
  for (int id = kChannels; id >= 1; --id) {
    text += " " + std::to_string(id) + " , " + std::to_string(id * 0.5) + " ,\t+1.5 \n\n";
  }
  const Calibration c = Calibration::parse(text, "t.csv");
  CHECK(c.elevation_deg[0] == Approx(0.5));
  CHECK(c.elevation_deg[39] == Approx(20.0));
  CHECK(c.azimuth_offset_deg[17] == Approx(1.5));
}

TEST_CASE("each kind of bad calibration file names its line and column", "[calibration]") {
  const std::string good = table("Laser id,Elevation,Azimuth", "\n", true);
  // Line 1 is the header, so channel N is on line N + 1.
  require_error(with_line(good, 4, "3,8.0"), "4:1", "expected 3 fields");
  require_error(with_line(good, 4, "3,8.0,1.0,7"), "4:1", "expected 3 fields");
  require_error(with_line(good, 5, "4,abc,1.0"), "5:3", "elevation is not a number");
  require_error(with_line(good, 5, "4,1.0,"), "5:7", "azimuth offset is not a number");
  require_error(with_line(good, 6, "5x,1.0,1.0"), "6:1", "channel id is not a number");
  require_error(with_line(good, 6, "2.5,1.0,1.0"), "6:1", "integer 1..40");
  require_error(with_line(good, 7, "41,1.0,1.0"), "7:1", "integer 1..40");
  require_error(with_line(good, 7, "0,1.0,1.0"), "7:1", "integer 1..40");
  require_error(with_line(good, 8, "3,1.0,1.0"), "8:1", "channel 3 already defined on line 4");
  require_error(with_line(good, 9, "8,91,1.0"), "9:3", "outside -90..90");
  require_error(with_line(good, 9, "8,1.0,-180.5"), "9:7", "outside -180..180");
  require_error(with_line(good, 9, "8,nan,1.0"), "9:3", "not a number");
  // One '+' at most, and never before a '-' (from_chars would read "-1" after the '+').
  require_error(with_line(good, 9, "8,+-1,1.0"), "9:3", "elevation is not a number");
  require_error(with_line(good, 9, "8,1.0,++1"), "9:7", "azimuth offset is not a number");
  require_error(with_line(good, 9, "8,+,1.0"), "9:3", "elevation is not a number");
  // Missing channels are reported after the last line, with the list of ids.
  std::string short_table = "Laser id,Elevation,Azimuth\n";
  for (int id = 1; id <= 38; ++id)
    short_table += std::to_string(id) + ",0,0\n";
  require_error(short_table, "40:1", "2 of 40 channels missing: 39,40");
  require_error("", "1:1", "40 of 40 channels missing");
}

TEST_CASE("an endless, huge or non-regular calibration file is refused at once", "[calibration]") {
  const test::ScratchDir dir("calibration-files");
  // A huge regular file: refused after a bounded read (one byte past the limit).
  const auto huge = dir / "huge.csv";
  std::ofstream(huge).close();
  std::filesystem::resize_file(huge, 4u << 20);
  CHECK_THROWS_WITH(load_calibration(huge.string()),
                    huge.string() + ":1:1: larger than 1048576 bytes: not a calibration table");
  // A device (endless) and a FIFO with no writer (an open would wait for one, a read forever):
  // refused before anything is read.
  const std::string not_regular =
      ": not a regular file (a FIFO, socket, device or directory): not a calibration table";
  CHECK_THROWS_WITH(load_calibration("/dev/zero"), "/dev/zero" + not_regular);
  const auto fifo = dir / "fifo.csv";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK_THROWS_WITH(load_calibration(fifo.string()), fifo.string() + not_regular);
}

TEST_CASE("loading a missing file is a clear error naming it", "[calibration]") {
  try {
    (void)load_calibration("/nonexistent/cal.csv");
    FAIL("no error");
  } catch (const CalibrationError& e) {
    CHECK(std::string(e.what()).find("/nonexistent/cal.csv") != std::string::npos);
  }
}

TEST_CASE("the nominal table is the Pandar40P design table", "[calibration]") {
  const Calibration c = Calibration::nominal();
  CHECK(c.is_nominal());
  CHECK(c.elevation_deg[0] == 15.0);
  CHECK(c.elevation_deg[5] == 2.0);
  CHECK(c.elevation_deg[11] == 0.0);
  CHECK(c.elevation_deg[38] == -19.0);
  CHECK(c.elevation_deg[39] == -25.0);
  // Elevations strictly decrease from channel 1 to channel 40.
  for (int ch = 1; ch < kChannels; ++ch)
    CHECK(c.elevation_deg[ch] < c.elevation_deg[ch - 1]);
  // Offsets: channels 1-6 and 31-40 at -1.042; 7, 10, ..., 28 at +3.125; 8, 11, ..., 29 at -5.208.
  for (int id = 1; id <= kChannels; ++id) {
    double expected = -1.042;
    if (id >= 7 && id <= 30 && (id - 7) % 3 == 0) expected = 3.125;
    if (id >= 7 && id <= 30 && (id - 7) % 3 == 1) expected = -5.208;
    INFO("channel " << id);
    CHECK(c.azimuth_offset_deg[id - 1] == expected);
  }
}

TEST_CASE("to_csv round-trips through parse", "[calibration]") {
  const Calibration nominal = Calibration::nominal();
  const Calibration again = Calibration::parse(nominal.to_csv(), "again.csv");
  CHECK(again.elevation_deg == nominal.elevation_deg);
  CHECK(again.azimuth_offset_deg == nominal.azimuth_offset_deg);
}

TEST_CASE("the real nebula calibration file loads with the spec's values", "[calibration][real]") {
  const auto path = test::real_capture("nebula_Pandar40P_calibration.csv");
  if (!path) return;
  const Calibration c = load_calibration(path->string());
  // Spec §3.2, nebula sample column.
  CHECK(c.elevation_deg[0] == Approx(14.794));
  CHECK(c.elevation_deg[33] == Approx(-10.133));
  CHECK(c.elevation_deg[39] == Approx(-24.985));
  CHECK(c.azimuth_offset_deg == Calibration::nominal().azimuth_offset_deg);
}
