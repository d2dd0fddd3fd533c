#include "support/mcap_reader.hpp"

#include <catch2/catch.hpp>
#include <cstdlib>

#include "support/test_support.hpp"

namespace pandarcap::test {

IndependentRead read_mcap_independently(const std::filesystem::path& file) {
  const std::filesystem::path dir =
      std::filesystem::path(PANDARCAP_SOURCE_DIR) / "tests" / "mcap_reader";
  IndependentRead result;
  const bool installed = std::filesystem::exists(dir / "node_modules" / "@mcap" / "core") &&
                         run_command("command -v node >/dev/null 2>&1").exit_code == 0;
  if (!installed) {
    result.reader_missing = true;
    const char* ci = std::getenv("CI");
    if (ci != nullptr && std::string(ci) == "true") {
      FAIL(
          "the independent MCAP reader is not installed under CI=true (.ci/install-deps runs "
          "npm ci in "
          << dir.string() << ")");
    }
    WARN("independent MCAP reader not installed (npm ci in " << dir.string() << "): not checked");
    return result;
  }
  const CommandResult r =
      run_command("node '" + (dir / "read_mcap.mjs").string() + "' '" + file.string() + "' 2>&1");
  if (r.exit_code != 0) {
    result.error = r.out.empty() ? "exit " + std::to_string(r.exit_code) : r.out;
    return result;
  }
  nlohmann::json parsed = nlohmann::json::parse(r.out, nullptr, false);
  if (parsed.is_discarded()) {
    result.error = "not JSON: " + r.out.substr(0, 400);
    return result;
  }
  result.file = std::move(parsed);
  return result;
}

}  // namespace pandarcap::test
