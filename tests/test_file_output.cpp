// The daemon's file layer: finished files never replace others, output directories are checked
// without being created, and one output directory has one daemon.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <string>

#include "bench/child_process.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/output/output_directories.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;

namespace {

void write(const fs::path& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}

}  // namespace

TEST_CASE("rename_no_replace refuses an existing name and leaves both files", "[outputs]") {
  test::ScratchDir dir("file-output-rename");
  write(dir / "new", "new");
  write(dir / "old", "old");
  CHECK_FALSE(rename_no_replace((dir / "new").c_str(), (dir / "old").c_str()));
  CHECK(harness::read_file(dir / "new") == "new");
  CHECK(harness::read_file(dir / "old") == "old");
  CHECK(rename_no_replace((dir / "new").c_str(), (dir / "free").c_str()));
  CHECK_FALSE(fs::exists(dir / "new"));
  CHECK(harness::read_file(dir / "free") == "new");
  CHECK_THROWS_AS(rename_no_replace((dir / "gone").c_str(), (dir / "x").c_str()),
                  std::system_error);
}

TEST_CASE("place_without_replacing takes the first free _dupN name", "[outputs]") {
  test::ScratchDir dir("file-output-place");
  const std::string taken = (dir / "frame_000001_20261122T120000.123Z.pcd").string();
  write(taken, "first");
  write(dir / "frame_000001_20261122T120000.123Z_dup1.pcd", "second");
  write(dir / ".tmp", "third");
  std::string to = taken;
  CHECK(place_without_replacing((dir / ".tmp").string(), to));
  // The extension is the last one: the stamp's ".123Z" stays in the stem.
  CHECK(to == (dir / "frame_000001_20261122T120000.123Z_dup2.pcd").string());
  CHECK(harness::read_file(to) == "third");
  CHECK(harness::read_file(taken) == "first");
  write(dir / ".tmp", "fourth");
  std::string free_name = (dir / "other.pcd").string();
  CHECK_FALSE(place_without_replacing((dir / ".tmp").string(), free_name));
  CHECK(free_name == (dir / "other.pcd").string());
}

TEST_CASE("output_problems: checks what would be created without creating it", "[outputs]") {
  test::ScratchDir dir("file-output-problems");
  WriterOptions o;
  o.output_dir = dir / "a" / "b";
  o.health_dir = o.output_dir / "health";
  o.prometheus_file = o.health_dir / "pandarcap.prom";
  CHECK(output_problems(o).empty());
  CHECK_FALSE(fs::exists(dir / "a"));  // nothing made

  write(dir / "file", "x");
  o.output_dir = dir / "file" / "out";
  o.health_dir = o.output_dir / "health";
  o.prometheus_file = o.health_dir / "pandarcap.prom";
  const auto problems = output_problems(o);
  REQUIRE(problems.size() == 1);  // one cause, said once
  CHECK(problems[0].find("'" + (dir / "file").string() + "' is not a directory") !=
        std::string::npos);

  o.output_dir = dir / "out";
  o.health_dir = dir / "out" / "health";
  o.prometheus_file = dir / "file" / "x.prom";
  const auto prom = output_problems(o);
  REQUIRE(prom.size() == 1);
  CHECK(prom[0].rfind("textfile directory", 0) == 0);
  o.prometheus = false;
  CHECK(output_problems(o).empty());
}

TEST_CASE("OutputDirectoryLock: one holder at a time, released with it", "[outputs]") {
  test::ScratchDir dir("file-output-lock");
  {
    OutputDirectoryLock first(dir / "out");
    CHECK(fs::exists(dir / "out" / "pandarcapd.lock"));
    CHECK(harness::read_file(dir / "out" / "pandarcapd.lock") == std::to_string(::getpid()) + "\n");
    try {
      OutputDirectoryLock second(dir / "out");
      FAIL("a second lock was granted");
    } catch (const OutputDirectoryBusy& busy) {
      CHECK(std::string(busy.what()).find("pid " + std::to_string(::getpid())) !=
            std::string::npos);
    }
  }
  CHECK_NOTHROW(OutputDirectoryLock(dir / "out"));
}
