// The test binary's main: Catch2's, and a failed run when the thread census (support/
// thread_census.hpp) found a test that starts threads without the [threads] tag.
#define CATCH_CONFIG_RUNNER
#include <catch2/catch.hpp>

#include "support/thread_census.hpp"

int main(int argc, char* argv[]) {
  const int result = Catch::Session().run(argc, argv);
  if (result == 0 && pandarcap::test::thread_census_failed()) return 1;
  return result;
}
