#include "support/thread_census.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <string_view>

// The listener interface (TestEventListenerBase) is compiled in only on request.
#define CATCH_CONFIG_EXTERNAL_INTERFACES
#include <catch2/catch.hpp>

namespace pandarcap::test {
namespace {

namespace fs = std::filesystem;

// The programs whose threads count: ours. Others a test runs (node, python3, tshark) start
// threads of their own that TSan would not see anyway.
constexpr std::array<std::string_view, 5> kOurPrograms = {
    "pandarcap_tests", "pandarcapd", "pandarcap-bench", "pandarcap-inspect", "pandarcap-ctl"};

bool failed = false;

bool census_preloaded() {
  const char* preload = std::getenv("LD_PRELOAD");
  return preload != nullptr && std::strstr(preload, "thread_census") != nullptr;
}

class ThreadCensus : public Catch::TestEventListenerBase {
 public:
  using TestEventListenerBase::TestEventListenerBase;

  void testCaseStarting(const Catch::TestCaseInfo& info) override {
    Catch::TestEventListenerBase::testCaseStarting(info);
    if (!census_preloaded()) return;
    // One file per test case and process (ctest runs tests side by side). Writable by everyone:
    // some tests run the daemon as nobody (setpriv).
    const fs::path dir = fs::temp_directory_path() / "pandarcap-thread-census";
    fs::create_directories(dir);
    ::chmod(dir.c_str(), 01777);
    census_ = dir / std::to_string(::getpid());
    std::ofstream(census_, std::ios::trunc).close();
    ::chmod(census_.c_str(), 0666);
    ::setenv("PANDARCAP_THREAD_CENSUS", census_.c_str(), 1);
  }

  void testCaseEnded(const Catch::TestCaseStats& stats) override {
    Catch::TestEventListenerBase::testCaseEnded(stats);
    if (census_.empty()) return;
    ::unsetenv("PANDARCAP_THREAD_CENSUS");
    std::map<std::string, int, std::less<>> threads;
    std::ifstream in(census_);
    for (std::string program; std::getline(in, program);) {
      if (std::find(kOurPrograms.begin(), kOurPrograms.end(), program) != kOurPrograms.end())
        ++threads[program];
    }
    std::error_code ec;
    fs::remove(census_, ec);
    census_.clear();
    std::string started;
    for (const auto& [program, n] : threads)
      started += (started.empty() ? "" : ", ") + std::to_string(n) + " in " + program;
    const auto& tags = stats.testInfo.tags;
    const bool tagged = std::find(tags.begin(), tags.end(), "threads") != tags.end();
    const std::string& name = stats.testInfo.name;
    if (!threads.empty() && !tagged) {
      std::fprintf(stderr,
                   "thread census: \"%s\" starts threads (%s) but is not tagged [threads]: the "
                   "TSan job runs only [threads] tests and would never check it. Add the tag.\n",
                   name.c_str(), started.c_str());
      failed = true;
    } else if (threads.empty() && tagged) {
      std::fprintf(stderr,
                   "thread census: warning: \"%s\" is tagged [threads] but started none here (did "
                   "it return early?); untagged, it would leave the TSan job.\n",
                   name.c_str());
    }
  }

 private:
  fs::path census_;
};

CATCH_REGISTER_LISTENER(ThreadCensus)

}  // namespace

bool thread_census_failed() {
  return failed;
}

}  // namespace pandarcap::test
