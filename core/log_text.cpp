#include "log_text.hpp"

namespace pandarcap {

std::string escaped_control(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  append_escaped_control(text, out);
  return out;
}

}  // namespace pandarcap
