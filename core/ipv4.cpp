#include "core/ipv4.hpp"

#include <arpa/inet.h>
#include <fmt/format.h>

#include <iterator>
#include <stdexcept>

namespace pandarcap {

std::optional<in_addr> parse_ipv4(const std::string& text) noexcept {
  in_addr address{};
  if (::inet_pton(AF_INET, text.c_str(), &address) != 1) return std::nullopt;
  return address;
}

std::optional<std::uint32_t> parse_ipv4_host_order(const std::string& text) noexcept {
  const auto address = parse_ipv4(text);
  if (!address) return std::nullopt;
  return ntohl(address->s_addr);
}

in_addr require_ipv4(const std::string& text, const char* what) {
  const auto address = parse_ipv4(text);
  if (!address) {
    throw std::invalid_argument(std::string(what) + " '" + text + "' is not an IPv4 address");
  }
  return *address;
}

sockaddr_in ipv4_endpoint(const std::string& text, std::uint16_t port, const char* what) {
  sockaddr_in endpoint{};
  endpoint.sin_family = AF_INET;
  endpoint.sin_port = htons(port);
  endpoint.sin_addr = require_ipv4(text, what);
  return endpoint;
}

void append_ipv4_source(std::string& out, std::uint64_t source) {
  if (source == 0) {
    out += "none";
    return;
  }
  const std::uint32_t ip = packed_ipv4(source);
  fmt::format_to(std::back_inserter(out), "{}.{}.{}.{}:{}", ip >> 24, (ip >> 16) & 0xFF,
                 (ip >> 8) & 0xFF, ip & 0xFF, packed_port(source));
}

void append_ipv4_source_json(std::string& out, std::uint64_t source) {
  if (source == 0) {
    out += "null";
    return;
  }
  out += '"';
  append_ipv4_source(out, source);
  out += '"';
}

}  // namespace pandarcap
