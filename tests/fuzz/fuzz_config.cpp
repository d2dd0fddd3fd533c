// Fuzz target: the TOML configuration loader. Any input either parses into a valid
// configuration or throws ConfigError; a parsed one prints (--print-config) and reads back to
// exactly the same text.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "config/config_loader.hpp"

using namespace pandarcap;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const DaemonConfig config = parse_config(text, "fuzz.toml");
    const std::string printed = to_toml(config);
    if (to_toml(parse_config(printed, "printed.toml")) != printed) std::abort();
  } catch (const ConfigError&) {
  }
  return 0;
}
