// The layout check: the tree keeps the shape docs/architecture.md describes. Every `#include` of
// ours goes the way the dependency table there allows (the table is read from the page, so the
// page is the rule); no source file outside tests/ grows past what one reading holds (600
// lines); daemon/'s root keeps the lifecycle only (at most 10 .cpp files), the source and output
// sides in their folders.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "bench/child_process.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kSourceDir{PANDARCAP_SOURCE_DIR};

// One row of the dependency table: the folder, and what it may include (folders end in '/').
struct Row {
  std::string folder;
  std::set<std::string> allowed;
  bool anything = false;  // "anything above", "anything"
};

// The rows of the table under "## Which way dependencies go" in docs/architecture.md.
std::map<std::string, Row> dependency_table() {
  const std::string page = pandarcap::harness::read_file(kSourceDir / "docs" / "architecture.md");
  const auto at = page.find("## Which way dependencies go");
  REQUIRE(at != std::string::npos);
  std::istringstream lines(page.substr(at));
  std::map<std::string, Row> rows;
  const std::regex code("`([^`]+)`");
  std::string line;
  while (std::getline(lines, line)) {
    if (line.rfind("| `", 0) != 0) continue;
    const auto split = line.find(" | ", 2);
    REQUIRE(split != std::string::npos);
    const std::string left = line.substr(0, split), right = line.substr(split + 3);
    std::set<std::string> allowed;
    for (std::sregex_iterator m(right.begin(), right.end(), code), end; m != end; ++m)
      allowed.insert((*m)[1].str());
    for (std::sregex_iterator m(left.begin(), left.end(), code), end; m != end; ++m) {
      Row row{(*m)[1].str(), allowed, right.find("anything") != std::string::npos};
      rows[row.folder] = row;
    }
  }
  return rows;
}

// The row a file belongs to: the longest folder of the table its path starts with.
std::optional<std::string> owner(const std::map<std::string, Row>& rows, const std::string& path) {
  std::optional<std::string> best;
  for (const auto& [folder, row] : rows) {
    if (path.rfind(folder, 0) == 0 && (!best || folder.size() > best->size())) best = folder;
  }
  return best;
}

// Every C++ source and header of ours under `folders` (node_modules is npm's, not ours), as paths
// relative to the source directory.
std::vector<std::string> sources_under(std::initializer_list<const char*> folders) {
  std::vector<std::string> files;
  for (const char* folder : folders) {
    for (const auto& entry : fs::recursive_directory_iterator(kSourceDir / folder)) {
      const fs::path& p = entry.path();
      if (p.string().find("node_modules") != std::string::npos) continue;
      if (p.extension() == ".cpp" || p.extension() == ".hpp")
        files.push_back(fs::relative(p, kSourceDir).generic_string());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

// The files of ours a source includes, as paths relative to the source directory: "x.hpp" next
// to the file, or from the project root ("core/sensors/packet.hpp"). System and library headers are
// not ours and are left out.
std::vector<std::string> our_includes(const std::string& file) {
  std::vector<std::string> found;
  std::istringstream lines(pandarcap::harness::read_file(kSourceDir / file));
  const std::regex include(R"re(^\s*#\s*include\s*"([^"]+)")re");
  std::string line;
  std::smatch m;
  while (std::getline(lines, line)) {
    if (!std::regex_search(line, m, include)) continue;
    const std::string name = m[1].str();
    const fs::path beside = fs::path(file).parent_path() / name;
    if (fs::exists(kSourceDir / beside)) {
      found.push_back(beside.lexically_normal().generic_string());
    } else if (fs::exists(kSourceDir / name)) {
      found.push_back(fs::path(name).lexically_normal().generic_string());
    }
  }
  return found;
}

bool allowed_by(const Row& row, const std::map<std::string, Row>& rows, const std::string& target) {
  if (row.anything || row.allowed.count(target) != 0) return true;
  const auto target_owner = owner(rows, target);
  return target_owner && (*target_owner == row.folder || row.allowed.count(*target_owner) != 0);
}

std::size_t line_count(const std::string& file) {
  const std::string text = pandarcap::harness::read_file(kSourceDir / file);
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

}  // namespace

TEST_CASE("every include goes the way docs/architecture.md's dependency table allows", "[layout]") {
  const auto rows = dependency_table();
  // The table has the folders the page's other sections name; a sanity floor, so an emptied or
  // renamed table cannot pass by allowing nothing to be checked.
  REQUIRE(rows.size() >= 15);
  REQUIRE(rows.count("daemon/source/") == 1);
  REQUIRE(rows.count("daemon/output/") == 1);
  std::size_t checked = 0;
  for (const std::string& file :
       sources_under({"ringbuf", "core", "config", "daemon", "bench", "tests"})) {
    const auto from = owner(rows, file);
    INFO(file);
    REQUIRE(from);  // every folder with code has a row
    const Row& row = rows.at(*from);
    for (const std::string& target : our_includes(file)) {
      INFO("includes " << target << " (row " << row.folder << ")");
      CHECK(allowed_by(row, rows, target));
      // Not in the table's words but in its sentences: tests/ is included by nothing else, bench/
      // by nothing of the product.
      if (row.folder.rfind("tests/", 0) != 0) CHECK(target.rfind("tests/", 0) != 0);
      if (row.folder.rfind("bench/", 0) != 0 && row.folder.rfind("tests/", 0) != 0)
        CHECK(target.rfind("bench/", 0) != 0);
      ++checked;
    }
  }
  CHECK(checked > 500);
}

TEST_CASE("the two sides of the daemon never include each other, nor the lifecycle's wiring",
          "[layout]") {
  // The table says it; this says it again in the one case a newcomer's edit is likeliest to
  // break, and proves the table check can fail: these includes are what a wrong move would add.
  const auto rows = dependency_table();
  const Row& source = rows.at("daemon/source/");
  const Row& output = rows.at("daemon/output/");
  for (const char* wiring : {"daemon/pipeline.hpp", "daemon/daemon_options.hpp",
                             "daemon/decode_worker.hpp", "daemon/startup_steps.hpp"}) {
    INFO(wiring);
    CHECK_FALSE(allowed_by(source, rows, wiring));
    CHECK_FALSE(allowed_by(output, rows, wiring));
  }
  CHECK_FALSE(allowed_by(source, rows, "daemon/output/writer.hpp"));
  CHECK_FALSE(allowed_by(output, rows, "daemon/source/udp_receiver.hpp"));
  CHECK(allowed_by(source, rows, "daemon/pipeline_types.hpp"));
  CHECK(allowed_by(output, rows, "daemon/pipeline_types.hpp"));
}

TEST_CASE("no source file outside tests/ is over 600 lines", "[layout]") {
  std::size_t files = 0;
  for (const std::string& file : sources_under({"ringbuf", "core", "config", "daemon", "bench"})) {
    INFO(file << ": " << line_count(file) << " lines");
    CHECK(line_count(file) <= 600);
    ++files;
  }
  CHECK(files > 100);
}

TEST_CASE(
    "daemon/'s root holds the lifecycle, and where packets come from and where results go "
    "have their folders",
    "[layout]") {
  std::vector<std::string> root_sources;
  for (const auto& entry : fs::directory_iterator(kSourceDir / "daemon")) {
    if (entry.path().extension() == ".cpp") root_sources.push_back(entry.path().filename());
  }
  INFO(root_sources.size() << " .cpp files in daemon/");
  CHECK(root_sources.size() <= 10);
  for (const char* moved :
       {"udp_receiver.cpp", "replay_source.cpp", "simulated_sender.cpp", "packet_source.cpp"}) {
    CHECK_FALSE(fs::exists(kSourceDir / "daemon" / moved));
    CHECK(fs::exists(kSourceDir / "daemon" / "source" / moved));
  }
  for (const char* moved : {"writer.cpp", "frame_output.cpp", "pcap_recorder.cpp",
                            "mcap_recorder.cpp", "health_publisher.cpp"}) {
    CHECK_FALSE(fs::exists(kSourceDir / "daemon" / moved));
    CHECK(fs::exists(kSourceDir / "daemon" / "output" / moved));
  }
}

TEST_CASE("a sensor model's code stays in core/sensors/ (and its simulator in core/sim/)",
          "[layout]") {
  // Outside those folders a model is reached through with_model() / kSensorModelIds and the
  // generic code: its type is named only where the one choice of a decoder is made, and no
  // file includes one model's header but the Pandar40P's (the default and its tuned decoder).
  const std::set<std::string> chooses = {"core/decode/any_stream_decoder.hpp",
                                         "core/decode/stream_decoder.cpp"};
  const std::regex model_type(R"(\b(Pandar64|PandarXT32|PandarXT16|PandarQT128|PandarXT<)\b)");
  const std::regex model_header(
      R"(#include "core/sensors/(pandar64|pandar_xt|pandar_qt128)\.hpp")");
  const std::regex comment(R"(//[^\n]*)");
  const std::regex text(R"("(\\.|[^"\\\n])*")");
  const std::regex raw_text(R"--(R"\(([\s\S]*?)\)")--");
  std::size_t files = 0;
  for (const std::string& file : sources_under({"ringbuf", "core", "config", "daemon", "bench"})) {
    if (file.rfind("core/sensors/", 0) == 0 || file.rfind("core/sim/", 0) == 0) continue;
    const std::string source = pandarcap::harness::read_file(kSourceDir / file);
    INFO(file);
    CHECK_FALSE(std::regex_search(source, model_header));
    // Comments and message text may name a model; code may not.
    const std::string code = std::regex_replace(
        std::regex_replace(std::regex_replace(source, raw_text, "\"\""), comment, ""), text,
        "\"\"");
    if (chooses.count(file) == 0) CHECK_FALSE(std::regex_search(code, model_type));
    ++files;
  }
  CHECK(files > 100);
}
